"""Put a grasped rod into a slot: the tactile pose used for position as well as angle.

The rod is held at an unknown in-hand angle and offset. The estimator gives both: the angle of the rod's axis
in the pad frame and the contact centroid, a point on that axis. The arm first turns the hand about the pad
normal through that point so the rod's axis is parallel to the slot, then translates it so the axis passes
through the slot's centre. The slot is a world feature (base frame) whose axis must lie in the pad plane.

Scored on the true rod pose: the axial angle between the rod and the slot in the pad plane, and the distance
from the slot's centre to the rod's axis (the lateral error); a placement succeeds when both are inside the
tolerances (the slot's clearance for the lateral error).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from tactile_manip.behaviours.skills import Abort, BehaviourConfig, approach, grasp, move_hand, read_pad
from tactile_manip.behaviours.task import ReportSection, Task, Trial, lateral_section, rounded
from tactile_manip.checks import check_array, check_finite_scalar
from tactile_manip.perception.pose import wrap_axial
from tactile_manip.robot.base import Arm, Gripper
from tactile_manip.robot.frames import angle_in_plane, hand_T_finger_pad, hand_T_pad, rotate_pose_about
from tactile_manip.sensors.base import TactileSensor
from tactile_manip.types import AngleEstimate

if TYPE_CHECKING:
    from tactile_manip.perception.tactile_estimator import TactileEstimator


@dataclass(frozen=True)
class Slot:
    """A straight slot in the base frame: centre point (m), axis direction, and lateral clearance (m)."""

    centre_base_m: np.ndarray
    axis_base: np.ndarray
    clearance_m: float = 0.001

    def __post_init__(self) -> None:
        check_array("Slot.centre_base_m", self.centre_base_m, shape=(3,))
        axis = check_array("Slot.axis_base", self.axis_base, shape=(3,))
        if not np.linalg.norm(axis) > 1e-9:
            raise ValueError("Slot.axis_base must be a non-zero vector")
        check_finite_scalar("Slot.clearance_m", self.clearance_m, low=0.0, low_open=True)


class PoseTruth(Protocol):
    """The held object's true pose (x axis along the rod), for scoring only."""

    def object_pose_base(self) -> np.ndarray | None:
        """base_T_object (4, 4), or None when unknown."""


@dataclass
class PlaceResult:
    """What :func:`place_in_slot` did; errors are None when not executed or no truth was given."""

    outcome: str
    detail: str = ""
    estimate: AngleEstimate | None = None
    angle_error_rad: float | None = None
    lateral_error_m: float | None = None
    timings_s: dict[str, float] = field(default_factory=dict)

    def succeeded(self, angle_tolerance_rad: float, clearance_m: float) -> bool:
        return (self.outcome == "done" and self.angle_error_rad is not None and self.lateral_error_m is not None
                and abs(self.angle_error_rad) <= angle_tolerance_rad and self.lateral_error_m <= clearance_m)


def place_in_slot(arm: Arm, gripper: Gripper, sensor: TactileSensor, estimator: TactileEstimator, slot: Slot, *,
                  object_width_m: float, config: BehaviourConfig | None = None,
                  truth: PoseTruth | None = None) -> PlaceResult:
    """Grasp the rod between the fingers, measure it, and move it into ``slot`` (see the module docstring).

    An undefined estimate aborts ("abstained"): without an axis there is nothing to align.
    """
    cfg = config or BehaviourConfig()
    result = PlaceResult(outcome="error")
    t0 = time.perf_counter()
    normal = (arm.state().base_T_hand @ hand_T_pad())[:3, 2]
    if abs(float(np.dot(np.asarray(slot.axis_base, float), normal))) > 1e-3 * np.linalg.norm(slot.axis_base):
        raise ValueError("the slot's axis must lie in the pad plane (perpendicular to the pad normal), "
                         f"got axis {np.asarray(slot.axis_base).tolist()} with the pad normal {normal.round(3).tolist()}")
    try:
        base_T_hand, width_m = grasp(arm, gripper, object_width_m, cfg)
        base_T_pad = base_T_hand @ hand_T_finger_pad(width_m)
        est = read_pad(sensor, estimator, cfg).angle  # the rod's axis and the contact centroid, a point on it
        result.estimate = est
        if not est.defined:
            raise Abort("abstained", f"no rod axis to align: {est.reason}")
        # a point on the rod's axis: the contact centroid, half the grasp width along the pad normal
        axis_point = (base_T_pad @ np.array([est.centroid_mm[0] * 1e-3, est.centroid_mm[1] * 1e-3,
                                             width_m / 2, 1.0]))[:3]
        turn = float(wrap_axial(angle_in_plane(np.asarray(slot.axis_base, float), base_T_pad) - est.angle_rad))
        move_hand(arm, rotate_pose_about(arm.state().base_T_hand, normal, axis_point, turn), cfg, "turn")
        approach(arm, np.asarray(slot.centre_base_m, float) - axis_point, cfg)
        result.outcome = "done"
    except Abort as stop:
        result.outcome, result.detail = stop.outcome, stop.detail
    result.timings_s["total"] = time.perf_counter() - t0
    pose = truth.object_pose_base() if truth is not None and result.outcome == "done" else None
    if pose is not None:
        result.angle_error_rad, result.lateral_error_m = slot_errors(pose, slot, base_T_pad)
    return result


def draw_slot(base_T_pad: np.ndarray, seed: int, clearance_m: float) -> Slot:
    """A slot in the pad plane of ``base_T_pad`` (4, 4), 4-6 cm beyond the pad centre along -pad y, at a random
    angle about the pad normal and up to 1 cm to either side, drawn from ``seed``."""
    rng = np.random.default_rng([seed, 1])
    angle = rng.uniform(-math.pi / 2, math.pi / 2)
    axis = base_T_pad[:3, :3] @ np.array([math.cos(angle), math.sin(angle), 0.0])
    centre_pad = np.array([rng.uniform(-0.01, 0.01), -rng.uniform(0.04, 0.06), 0.0, 1.0])
    return Slot(centre_base_m=(base_T_pad @ centre_pad)[:3], axis_base=axis, clearance_m=clearance_m)


def slot_errors(base_T_object: np.ndarray, slot: Slot, base_T_pad: np.ndarray) -> tuple[float, float]:
    """(axial angle rod - slot in the pad plane, rad; distance from the slot centre to the rod axis, m)."""
    axis = base_T_object[:3, 0] / np.linalg.norm(base_T_object[:3, 0])
    angle = float(wrap_axial(angle_in_plane(axis, base_T_pad)
                             - angle_in_plane(np.asarray(slot.axis_base, float), base_T_pad)))
    offset = np.asarray(slot.centre_base_m, float) - base_T_object[:3, 3]
    lateral = float(np.linalg.norm(offset - np.dot(offset, axis) * axis))
    return angle, lateral


@dataclass(frozen=True)
class PlaceConfig:
    """The slot of the placement (a scene's ``[place]`` table): drawn per presentation in the pad plane, 4-6 cm
    beyond the pad centre along -pad y, at a random angle; a placement succeeds with the rod within the scene's
    ``tolerance_deg`` of the slot's axis and its axis within ``clearance_mm`` of the slot's centre."""

    clearance_mm: float = 1.0

    def __post_init__(self) -> None:
        check_finite_scalar("place.clearance_mm", self.clearance_mm, low=0.0, low_open=True, high=50.0)


class Place(Task):
    """Put the grasped rod into a slot drawn per presentation (:func:`place_in_slot`); ``error_rad`` is the
    rod's axial angle to the slot, ``lateral_error_mm`` the distance from the slot's centre to its axis."""

    name = "place"
    title = "Slot placement trials"
    Config = PlaceConfig
    simulated_only = "the slot is a world feature the twin knows"

    def run(self, trial: Trial) -> PlaceResult:
        base_T_pad = trial.arm.state().base_T_hand @ hand_T_pad()  # the fingers' mid-plane before the grasp
        slot = draw_slot(base_T_pad, trial.seed, self.config.clearance_mm * 1e-3)
        return place_in_slot(trial.arm, trial.gripper, trial.sensor, trial.estimator, slot,
                             object_width_m=trial.object_width_m, config=self.behaviour, truth=trial.truth)

    def failed(self, outcome: str, detail: str) -> PlaceResult:
        return PlaceResult(outcome=outcome, detail=detail)

    def record(self, result: PlaceResult) -> dict[str, Any]:
        outcome, detail = result.outcome, result.detail
        if outcome == "done" and (result.angle_error_rad is None or result.lateral_error_m is None):
            outcome, detail = "unmeasured", "the rod's final pose was not measured"
        return {"outcome": outcome, "detail": detail, "target_angle_rad": 0.0,
                "error_rad": result.angle_error_rad if outcome == "done" else None,
                "lateral_error_mm": rounded(None if result.lateral_error_m is None else result.lateral_error_m * 1e3),
                "clearance_mm": float(self.config.clearance_mm)}

    @classmethod
    def report(cls, records: Sequence[Any]) -> list[ReportSection]:
        return [lateral_section(records, "Lateral error (placed rods)", "placed")]

    @classmethod
    def success_rule(cls, records: Sequence[Any]) -> str:
        clearance = next((r.clearance_mm for r in records if r.clearance_mm is not None), None)
        return (f"Success: outcome `done`, the rod's axis within {clearance:g} mm (the slot's clearance) of the "
                "slot's centre, and |rod - slot axis| <=")
