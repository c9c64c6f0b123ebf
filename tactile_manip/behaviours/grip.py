"""Grip to a target force with the object centred on the pad: contact state in the loop.

A gripper's force control is open loop: it closes until its motor current says the threshold is reached, and
the force the object then feels depends on the object's compliance and the fingers' friction (on a Franka Hand,
tens of percent away from the command). With a contact model of the sensor's board the pad measures the force
itself. The behaviour:

1. closes on the object at the target force;
2. reads the sensor (``frames`` frames averaged) through one estimator that gives the in-hand angle, the contact
   state and the contact's position (:class:`~tactile_manip.perception.tactile_estimator.TactileEstimator`);
3. **centres**: where the object's axis is more than ``centre_tolerance_mm`` from the pad centre, opens, moves
   the hand in the pad plane so the pad centre comes onto the axis, and closes again (up to ``max_recentres``);
4. **servoes the force**: the gripper's force gain (felt / commanded) is estimated from every reading so far,
   each weighted by its sigma, with the gripper's own force error (``command_sigma_n``) as the prior; while the
   force that gain implies is more than ``force_deadband_n`` off the target, the command becomes target / gain
   and the gripper grasps again (up to ``max_force_steps``). A reading whose sigma is large next to the gripper's
   own error moves the command little: a contact model that has not seen the object cannot make the grip worse
   than the gripper alone by much;
5. reports the last estimate: angle, contact state and position.

Without a contact model (the estimates' ``contact`` is None: the blind baseline, or an estimator given none)
steps 3 and 4 are skipped: the grasp stays at the commanded force wherever the object sits, which is what a
gripper without touch does. A rod's contact is a line across the pad; its position estimate is a point on that
line, so centring moves the pad centre onto the rod's axis (across it), never along it.

Scored on the truth (simulation): the force the object feels against the target, the distance from the pad
centre to the rod's axis, and the estimated in-hand angle against the true one.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from tactile_manip.behaviours.skills import Abort, BehaviourConfig, close_on, grasp, move_hand, read_pad, release
from tactile_manip.behaviours.task import ReportSection, Task, Trial, fmt2, lateral_section, percentile, rounded
from tactile_manip.checks import check_finite_scalar
from tactile_manip.errors import ArmFault
from tactile_manip.perception.pose import wrap_axial
from tactile_manip.robot.base import Arm, Gripper
from tactile_manip.robot.frames import hand_T_finger_pad
from tactile_manip.sensors.base import TactileSensor
from tactile_manip.types import AngleEstimate

if TYPE_CHECKING:
    from tactile_manip.perception.contact import ContactState
    from tactile_manip.perception.tactile_estimator import TactileEstimate, TactileEstimator

# one force step scales the command by at most this factor either way: a wild reading cannot slam the fingers
MAX_FORCE_STEP_RATIO = 2.0
MIN_FORCE_SIGMA_N = 0.01  # a reading without a sigma (or a smaller one) counts as this sure, N


@dataclass(frozen=True)
class GripConfig:
    """What the "grip" task asks for; the target force is the behaviour's ``force_n``.

    Attributes:
        force_tolerance_n: a grip succeeds with the force the object feels within this of the target, N.
        force_deadband_n: the force servo stops once the measured force is within this of the target, N.
        centre_tolerance_mm: a grip succeeds with the object's axis within this of the pad centre, mm; the
            behaviour re-centres an object it measures farther off.
        max_force_steps: force corrections (each a grasp at a new command) before the behaviour stops.
        max_recentres: centring moves (open, shift, close) before the behaviour stops.
        command_sigma_n: the gripper's force error at the target (one sigma, N): the prior of the force gain the
            readings are weighed against; 0 trusts the readings alone.
    """

    force_tolerance_n: float = 1.5
    force_deadband_n: float = 0.5
    centre_tolerance_mm: float = 0.5
    max_force_steps: int = 3
    max_recentres: int = 1
    command_sigma_n: float = 0.0

    def __post_init__(self) -> None:
        check_finite_scalar("grip.force_tolerance_n", self.force_tolerance_n, low=0.0, low_open=True, high=50.0)
        check_finite_scalar("grip.force_deadband_n", self.force_deadband_n, low=0.0, high=50.0)
        check_finite_scalar("grip.centre_tolerance_mm", self.centre_tolerance_mm, low=0.0, low_open=True,
                            high=20.0)
        check_finite_scalar("grip.command_sigma_n", self.command_sigma_n, low=0.0, high=50.0)
        for name in ("max_force_steps", "max_recentres"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 10:
                raise ValueError(f"grip.{name} must be an integer in [0, 10], got {value!r}")


class GripTruth(Protocol):
    """What the object really feels and where it really is (for scoring only; the behaviour never reads it)."""

    def object_pose_base(self) -> np.ndarray | None:
        """base_T_object (4, 4), x along the rod's axis, or None when unknown."""

    def grip_force_n(self) -> float | None:
        """The normal force the object feels now, N, or None when unknown."""


@dataclass
class GripResult:
    """What :func:`grip_to_force` did; the errors are None when the grip was not completed or no truth was given.

    ``commanded_force_n`` is the last command; ``contact`` the last contact state (None without a contact model).
    ``angle_error_rad`` is the estimated in-hand angle minus the true one (axial); ``centre_error_m`` the
    distance from the pad centre to the rod's axis; ``force_error_n`` the force the object feels minus the target.
    """

    outcome: str
    detail: str = ""
    estimate: AngleEstimate | None = None
    contact: ContactState | None = None
    position_mm: tuple[float, float] | None = None
    commanded_force_n: float | None = None
    force_steps: int = 0
    recentres: int = 0
    true_force_n: float | None = None
    force_error_n: float | None = None
    centre_error_m: float | None = None
    angle_error_rad: float | None = None
    timings_s: dict[str, float] = field(default_factory=dict)


def grip_to_force(arm: Arm, gripper: Gripper, sensor: TactileSensor, estimator: TactileEstimator, *,
                  object_width_m: float, config: BehaviourConfig | None = None, grip: GripConfig | None = None,
                  truth: GripTruth | None = None) -> GripResult:
    """Grasp the object, centre it and servo the grip force to ``config.force_n`` (module docstring).

    ``estimator``: its estimates give the angle, the contact state and the position: the closed loop; where
    they carry no contact state (no contact model) the loop stays open (the grasp stays as commanded). Every
    fault ends in an outcome of the result, never an escape.
    """
    cfg = config or BehaviourConfig()
    spec = grip or GripConfig()
    result = GripResult(outcome="error", commanded_force_n=cfg.force_n)
    t0 = time.perf_counter()
    try:
        _, width_m = grasp(arm, gripper, object_width_m, cfg)
        est = read_pad(sensor, estimator, cfg)
        closed_loop = est.contact is not None
        if closed_loop:
            est = _centre(arm, gripper, sensor, estimator, width_m, cfg, spec, result, est)
            est = _servo_force(gripper, sensor, estimator, width_m, cfg, spec, result, est)
        _keep(result, est, closed_loop)
        if not result.estimate.defined:
            raise Abort("abstained", f"no in-hand angle: {result.estimate.reason}")
        result.outcome = "done"
    except Abort as stop:
        result.outcome, result.detail = stop.outcome, stop.detail
    result.timings_s["total"] = time.perf_counter() - t0
    if truth is not None and result.outcome == "done":
        _score(result, arm, truth, cfg.force_n, width_m)
    return result


def _keep(result: GripResult, est: TactileEstimate, closed_loop: bool) -> None:
    if closed_loop:
        result.estimate, result.contact, result.position_mm = est.angle, est.contact, est.position_mm
    else:
        result.estimate = est.angle


def _centre(arm: Arm, gripper: Gripper, sensor: TactileSensor, estimator: TactileEstimator, width_m: float,
            cfg: BehaviourConfig, spec: GripConfig, result: GripResult, est: TactileEstimate) -> TactileEstimate:
    """Move the pad centre onto the object's axis while the measured offset exceeds the tolerance."""
    while result.recentres < spec.max_recentres:
        shift_mm = _axis_offset_mm(est)
        if shift_mm is None or math.hypot(*shift_mm) <= spec.centre_tolerance_mm:
            return est
        result.recentres += 1
        try:
            base_T_hand = arm.state().base_T_hand
        except ArmFault as exc:
            raise Abort("arm_fault", f"arm state unavailable before centring: {exc}") from None
        release(gripper, width_m, "opening to centre")
        base_T_pad = base_T_hand @ hand_T_finger_pad(width_m)
        target = base_T_hand.copy()
        target[:3, 3] += base_T_pad[:3, :2] @ (np.asarray(shift_mm) * 1e-3)
        move_hand(arm, target, cfg, "centring move")
        close_on(gripper, width_m, cfg, "centred grasp", force_n=result.commanded_force_n)
        est = read_pad(sensor, estimator, cfg)
    return est


def _axis_offset_mm(est: TactileEstimate) -> tuple[float, float] | None:
    """The shortest move (pad frame, mm) that puts the pad centre on the object's axis: across the axis where
    the angle is measured (the position is a point on it), else (no angle, or the blind prior's, which no reading
    made) to the contact's position; None without one."""
    if est.position_mm is None:
        return None
    p = np.asarray(est.position_mm, np.float64)
    if est.angle.defined and est.angle.source != "prior":
        axis = np.array([math.cos(est.angle.angle_rad), math.sin(est.angle.angle_rad)])
        p = p - float(p @ axis) * axis
    return float(p[0]), float(p[1])


def _servo_force(gripper: Gripper, sensor: TactileSensor, estimator: TactileEstimator, width_m: float,
                 cfg: BehaviourConfig, spec: GripConfig, result: GripResult, est: TactileEstimate) -> TactileEstimate:
    """Command target / gain, the gain (felt / commanded force) estimated from every reading so far weighted by
    its sigma and the gripper's prior, until the force it implies is within the deadband of the target."""
    target = cfg.force_n
    # precision-weighted sum of gain readings; the prior: gain 1 with the gripper's own error
    prior = (target / spec.command_sigma_n) ** 2 if spec.command_sigma_n > 0 else 0.0
    weight, weighted = prior, prior * 1.0
    while True:
        measured = est.contact.force_n if est.contact.plausible else None
        if measured is None or not math.isfinite(measured) or measured <= 0.0:
            return est  # nothing to act on: the grasp stays as commanded
        command = result.commanded_force_n
        sigma = est.contact.force_sigma_n
        w = (command / max(sigma, MIN_FORCE_SIGMA_N)) ** 2 if sigma is not None and math.isfinite(sigma) \
            else (command / MIN_FORCE_SIGMA_N) ** 2
        weight, weighted = weight + w, weighted + w * measured / command
        gain = weighted / weight
        if abs(gain * command - target) <= spec.force_deadband_n or result.force_steps >= spec.max_force_steps:
            return est
        ratio = min(max(target / (gain * command), 1.0 / MAX_FORCE_STEP_RATIO), MAX_FORCE_STEP_RATIO)
        result.force_steps += 1
        result.commanded_force_n = min(max(command * ratio, 0.5), gripper.max_force_n)
        close_on(gripper, width_m, cfg, "force correction", force_n=result.commanded_force_n)
        est = read_pad(sensor, estimator, cfg)


def _score(result: GripResult, arm: Arm, truth: GripTruth, target_n: float, width_m: float) -> None:
    force = truth.grip_force_n()
    if force is not None:
        result.true_force_n = float(force)
        result.force_error_n = float(force) - target_n
    pose = truth.object_pose_base()
    if pose is None:
        return
    base_T_pad = arm.state().base_T_hand @ hand_T_finger_pad(width_m)
    pad_T_object = np.linalg.inv(base_T_pad) @ pose
    axis = pad_T_object[:2, 0]
    axis = axis / np.linalg.norm(axis)
    point = pad_T_object[:2, 3]
    result.centre_error_m = float(np.linalg.norm(point - float(point @ axis) * axis))
    if result.estimate is not None and result.estimate.defined:
        true_angle = math.atan2(axis[1], axis[0])
        result.angle_error_rad = float(wrap_axial(result.estimate.angle_rad - true_angle))


class Grip(Task):
    """Grip the rod at the behaviour's ``force_n``, centred on the pad (:func:`grip_to_force`); ``error_rad`` is
    the estimated in-hand angle minus the true one, ``lateral_error_mm`` the distance from the pad centre to the
    rod's axis, ``force_error_n`` the force the rod felt minus the target."""

    name = "grip"
    title = "Grip-to-force trials"
    Config = GripConfig
    simulated_only = "it is scored on the force the object feels, which only the twin knows"

    @classmethod
    def check_scene(cls, scene: Any) -> None:
        super().check_scene(scene)
        if not scene.contact_model and not any(m.contact_model for m in scene.methods):
            raise ValueError(f"task = {scene.task!r} needs a contact_model (the force and position it servoes on), "
                             "e.g. contact_model = \"models/contact_supermag.onnx\"")

    def run(self, trial: Trial) -> GripResult:
        return grip_to_force(trial.arm, trial.gripper, trial.sensor, trial.estimator,
                             object_width_m=trial.object_width_m, config=self.behaviour, grip=self.config,
                             truth=trial.truth)

    def failed(self, outcome: str, detail: str) -> GripResult:
        return GripResult(outcome=outcome, detail=detail)

    def record(self, result: GripResult) -> dict[str, Any]:
        outcome, detail = result.outcome, result.detail
        measured = None not in (result.angle_error_rad, result.centre_error_m, result.force_error_n)
        if outcome == "done" and not measured:
            outcome, detail = "unmeasured", "the final force or pose was not measured"
        state = result.contact if result.contact is not None and result.contact.plausible else None
        return {"outcome": outcome, "detail": detail, "target_angle_rad": 0.0,
                "action": "regrasp" if result.recentres or result.force_steps else "act",
                "regrasps": result.recentres + result.force_steps,
                "error_rad": result.angle_error_rad if outcome == "done" else None,
                "lateral_error_mm": rounded(None if result.centre_error_m is None else result.centre_error_m * 1e3),
                "clearance_mm": float(self.config.centre_tolerance_mm), "force_error_n": rounded(result.force_error_n),
                "force_tolerance_n": float(self.config.force_tolerance_n),
                "estimated_grip_force_n": rounded(None if state is None else state.force_n),
                "estimated_grip_force_sigma_n": rounded(None if state is None else state.force_sigma_n),
                "extra": {"commanded_force_n": float(self.behaviour.force_n),
                          "final_command_n": rounded(result.commanded_force_n),
                          "applied_force_n": rounded(result.true_force_n), "force_steps": result.force_steps,
                          "recentres": result.recentres,
                          "position_mm": None if result.position_mm is None else [round(v, 4) for v in
                                                                                  result.position_mm]}}

    @classmethod
    def report(cls, records: Sequence[Any]) -> list[ReportSection]:
        return [lateral_section(records, "Centring: the rod's axis from the pad centre", "gripped"),
                force_section(records)]

    @classmethod
    def success_rule(cls, records: Sequence[Any]) -> str:
        clearance = next((r.clearance_mm for r in records if r.clearance_mm is not None), None)
        force = next((r.force_tolerance_n for r in records if r.force_tolerance_n is not None), None)
        return (f"Success: outcome `done`, the force the rod feels within {force:g} N of the target, the rod's axis "
                f"within {clearance:g} mm of the pad centre, and |estimated - true in-hand angle| <=")


def force_errors(records: Sequence[Any]) -> dict[str, dict[str, Any]]:
    """Per method, the force the rod felt against the target in a run's records (N): how many grips measured it,
    RMSE, median and p95 of |error|, mean error, how many are within the tolerance, and the mean number of force
    corrections (None where a method measured none)."""
    out = {}
    for method in dict.fromkeys(r.method for r in records):
        mine = [r for r in records if r.method == method and r.force_error_n is not None]
        err = np.array([r.force_error_n for r in mine], np.float64)
        out[method] = {"n": len(mine), "rmse_n": float(np.sqrt(np.mean(err ** 2))) if mine else None,
                       "median_abs_n": percentile(np.abs(err), 50), "p95_abs_n": percentile(np.abs(err), 95),
                       "mean_n": float(err.mean()) if mine else None,
                       "within_tolerance": sum(r.within_force for r in mine),
                       "mean_force_steps": (float(np.mean([r.extra.get("force_steps", 0) for r in mine])) if mine
                                            else None)}
    return out


def force_section(records: Sequence[Any]) -> ReportSection:
    """The report's section of the force the rod felt against the target, per method."""
    errors = force_errors(records)
    rows = [[m, str(e["n"]), fmt2(e["rmse_n"]), fmt2(e["median_abs_n"]), fmt2(e["p95_abs_n"]), fmt2(e["mean_n"]),
             f"{e['within_tolerance']}/{e['n']}",
             "-" if e["mean_force_steps"] is None else f"{e['mean_force_steps']:.1f}"]
            for m, e in errors.items()]
    return ReportSection("force_error", errors, "Grip force: what the rod felt against the target",
                         ["method", "gripped", "RMSE (N)", "median abs (N)", "p95 abs (N)", "mean (N)",
                          "within tolerance", "mean force steps"], rows)
