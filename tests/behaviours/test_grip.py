"""The grip behaviour: centre the rod on the pad and servo the grip force on the contact state."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tactile_manip.behaviours.grip import GripConfig, GripResult, grip_to_force
from tactile_manip.behaviours.skills import BehaviourConfig
from tactile_manip.perception.contact import ContactState
from tactile_manip.perception.tactile_estimator import TactileEstimate, TactileEstimator
from tactile_manip.trials.cells import SimulatedCell
from tactile_manip.trials.methods import build_pose_estimators, build_tactile_estimators
from tactile_manip.trials.presentation import draw_presentation
from tactile_manip.trials.scene import MethodSpec, PresentationConfig, TrialObject, TrialScene

pytest.importorskip("roboticstoolbox")
pytest.importorskip("onnxruntime")

MODELS = Path(__file__).resolve().parents[2] / "models"
TARGET_N = 8.0


@pytest.fixture(scope="module")
def cell():
    scene = TrialScene(trials=4, seed=3, methods=[MethodSpec("supermag", str(MODELS / "supermag.onnx"))],
                       behaviour=BehaviourConfig(force_n=TARGET_N),
                       presentation=PresentationConfig(offset_mm=2.0, force_n=(5.0, 11.0), objects=[
                           TrialObject("hex_bar", "h8", {"size_mm": 8.0})]))
    cell = SimulatedCell(scene)
    with cell.connected():
        yield cell


class OracleForce:
    """An estimator's angle and position with the force the cell really applies: what a perfect contact
    model would read, so the servo and the centring are tested apart from any model's error."""

    def __init__(self, cell: SimulatedCell, estimator: TactileEstimator) -> None:
        self.cell, self.estimator = cell, estimator
        self.reads: list[float] = []

    def read(self, sensor, *, frames: int = 1, timeout_s: float = 0.1) -> TactileEstimate:
        angle = self.estimator.read(sensor, frames=frames, timeout_s=timeout_s).angle
        force = self.cell.applied_force_n
        self.reads.append(force)
        return TactileEstimate(angle=angle, contact=ContactState(in_contact=True, force_n=force, force_sigma_n=0.1),
                               position_mm=angle.centroid_mm)


def _presentation_off_target(cell, low_n: float):
    """A presentation whose rod is gripped with at least ``low_n`` N of error by the command alone and sits at
    least 1 mm off the pad centre."""
    for trial in range(200):
        p = draw_presentation(cell.scene, trial)
        if abs(p.force_n - TARGET_N) >= low_n and math.hypot(*p.offset_mm) >= 1.0:
            return p
    raise AssertionError("no such presentation")


def _grip(cell, p, estimator, grip: GripConfig | None = None) -> GripResult:
    """Present ``p`` and grip it with ``estimator``, scored on the cell's truth."""
    with cell.presented(p) as (obj, truth):
        return grip_to_force(cell.arm, cell.gripper, cell.sensor, estimator, object_width_m=obj.width_m,
                             config=cell.scene.behaviour, grip=grip, truth=truth)


def test_the_servo_brings_the_felt_force_to_the_target_and_centres_the_rod(cell) -> None:
    p = _presentation_off_target(cell, 2.0)
    oracle = OracleForce(cell, build_tactile_estimators(cell.scene)["supermag"])
    grip = GripConfig(force_tolerance_n=1.0, force_deadband_n=0.2, centre_tolerance_mm=0.3)
    result = _grip(cell, p, oracle, grip)
    assert result.outcome == "done", result.detail
    assert abs(oracle.reads[0] - p.force_n) < 1e-9          # the first grasp felt the presentation's force
    assert result.force_steps >= 1 and abs(result.force_error_n) <= grip.force_deadband_n + 1e-9
    assert result.commanded_force_n == pytest.approx(TARGET_N * TARGET_N / p.force_n, rel=1e-6)
    assert result.recentres == 1 and result.centre_error_m * 1e3 < grip.centre_tolerance_mm
    assert abs(math.degrees(result.angle_error_rad)) < 5.0


def test_without_a_contact_model_the_grip_stays_as_commanded(cell) -> None:
    p = _presentation_off_target(cell, 2.0)
    plain = build_tactile_estimators(cell.scene)["supermag"]  # the scene names no contact model
    assert plain.contact is None
    result = _grip(cell, p, plain)
    assert result.outcome == "done" and result.force_steps == 0 and result.recentres == 0
    assert result.commanded_force_n == TARGET_N and result.contact is None
    assert result.force_error_n == pytest.approx(p.force_n - TARGET_N)
    # the rod stays where it was presented: its axis is as far from the pad centre as the presentation put it
    assert result.centre_error_m * 1e3 <= math.hypot(*p.offset_mm) + 1e-6


def test_the_shipped_contact_model_closes_the_loop(cell) -> None:
    from tactile_manip.perception.contact import ContactEstimator

    both = TactileEstimator(build_pose_estimators(cell.scene)["supermag"],
                            ContactEstimator(MODELS / "contact_supermag.onnx"))
    p = _presentation_off_target(cell, 2.0)
    result = _grip(cell, p, both)
    assert result.outcome == "done", result.detail
    assert result.contact is not None and result.contact.plausible
    assert result.position_mm is not None
    # an 8 mm hex bar: wide enough for the model of other shapes to read it within about 1 N, so the servo
    # brings the felt force nearer the target than the command alone
    assert result.force_steps >= 1 and result.commanded_force_n != TARGET_N
    assert abs(result.force_error_n) < abs(p.force_n - TARGET_N) - 0.5


def test_a_sensor_that_stops_ends_the_grip_as_stale(cell) -> None:
    plain = build_tactile_estimators(cell.scene)["supermag"]
    with cell.presented(draw_presentation(cell.scene, 0), sensor_stall=True) as (obj, truth):
        result = grip_to_force(cell.arm, cell.gripper, cell.sensor, plain, object_width_m=obj.width_m,
                               config=cell.scene.behaviour, truth=truth)
    assert isinstance(result, GripResult)
    assert result.outcome == "sensor_stale" and result.force_error_n is None


def test_a_grasp_of_the_held_rod_sets_the_force_the_sensor_sees(cell) -> None:
    p = draw_presentation(cell.scene, 1)
    with cell.presented(p) as (obj, _):
        cell.gripper.grasp(obj.width_m, TARGET_N)
        first = cell.applied_force_n
        cell.gripper.grasp(obj.width_m, TARGET_N / 2)
        assert cell.gripper.state().is_grasped
        assert cell.applied_force_n == pytest.approx(first / 2)
    assert cell.applied_force_n is None  # released at the trial's end


@pytest.mark.parametrize("kwargs, match", [
    ({"force_tolerance_n": 0.0}, "force_tolerance_n"),
    ({"force_deadband_n": float("nan")}, "force_deadband_n"),
    ({"centre_tolerance_mm": -1.0}, "centre_tolerance_mm"),
    ({"max_force_steps": 11}, "max_force_steps"),
    ({"max_recentres": True}, "max_recentres"),
])
def test_grip_config_refuses_bad_values(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        GripConfig(**kwargs)


def test_the_gripper_prior_weighs_an_unsure_reading_down(cell) -> None:
    """With the gripper's own error as the prior, a reading as unsure as it moves the command about half way."""
    class Unsure(OracleForce):
        def read(self, sensor, *, frames: int = 1, timeout_s: float = 0.1) -> TactileEstimate:
            est = super().read(sensor, frames=frames, timeout_s=timeout_s)
            return TactileEstimate(angle=est.angle, contact=ContactState(in_contact=True, force_n=est.contact.force_n,
                                                                         force_sigma_n=2.0),
                                   position_mm=est.position_mm)

    p = _presentation_off_target(cell, 2.0)
    unsure = Unsure(cell, build_tactile_estimators(cell.scene)["supermag"])
    grip = GripConfig(force_deadband_n=0.01, max_force_steps=1, command_sigma_n=2.0)
    result = _grip(cell, p, unsure, grip)
    gain = (1.0 + p.force_n / TARGET_N) / 2  # equal weights: the prior's gain 1 and the reading's
    assert result.force_steps == 1
    assert result.commanded_force_n == pytest.approx(TARGET_N / gain, rel=1e-6)


def test_a_contact_state_that_is_no_answer_leaves_the_grip_as_commanded(cell) -> None:
    """An implausible state has no force: the servo does not act on it (nor on a non-positive force)."""
    class NoAnswer(OracleForce):
        def __init__(self, cell, estimator, state: ContactState) -> None:
            super().__init__(cell, estimator)
            self.state = state

        def read(self, sensor, *, frames: int = 1, timeout_s: float = 0.1) -> TactileEstimate:
            est = super().read(sensor, frames=frames, timeout_s=timeout_s)
            return TactileEstimate(angle=est.angle, contact=self.state, position_mm=est.position_mm)

    p = _presentation_off_target(cell, 2.0)
    for state in (ContactState(in_contact=True, plausible=False, implausible_reason="a chip beyond its range"),
                  ContactState(in_contact=True, force_n=-0.3, force_sigma_n=0.5)):
        estimator = NoAnswer(cell, build_tactile_estimators(cell.scene)["supermag"], state)
        result = _grip(cell, p, estimator)
        assert result.outcome == "done" and result.force_steps == 0 and result.commanded_force_n == TARGET_N
        assert result.force_error_n == pytest.approx(p.force_n - TARGET_N)
