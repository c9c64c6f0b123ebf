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

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np

from tactile_manip.behaviours.reorient import ReorientConfig, _Abort, _close_on, _grasp, _move_hand
from tactile_manip.checks import check_finite_scalar
from tactile_manip.errors import ArmFault, GripperError, SensorError
from tactile_manip.perception.pose import wrap_axial
from tactile_manip.robot.base import Arm, Gripper
from tactile_manip.robot.frames import hand_T_finger_pad
from tactile_manip.robot.twin_hand import GRIPPER_MAX_FORCE_N
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
                  object_width_m: float, config: ReorientConfig | None = None, grip: GripConfig | None = None,
                  truth: GripTruth | None = None) -> GripResult:
    """Grasp the object, centre it and servo the grip force to ``config.force_n`` (module docstring).

    ``estimator``: its estimates give the angle, the contact state and the position: the closed loop; where
    they carry no contact state (no contact model) the loop stays open (the grasp stays as commanded). Every
    fault ends in an outcome of the result, never an escape.
    """
    cfg = config or ReorientConfig()
    spec = grip or GripConfig()
    result = GripResult(outcome="error", commanded_force_n=cfg.force_n)
    t0 = time.perf_counter()
    try:
        _, width_m = _grasp(arm, gripper, object_width_m, cfg)
        est = _read_all(sensor, estimator, cfg)
        closed_loop = est.contact is not None
        if closed_loop:
            est = _centre(arm, gripper, sensor, estimator, width_m, cfg, spec, result, est)
            est = _servo_force(gripper, sensor, estimator, width_m, cfg, spec, result, est)
        _keep(result, est, closed_loop)
        if not result.estimate.defined:
            raise _Abort("abstained", f"no in-hand angle: {result.estimate.reason}")
        result.outcome = "done"
    except _Abort as stop:
        result.outcome, result.detail = stop.outcome, stop.detail
    result.timings_s["total"] = time.perf_counter() - t0
    if truth is not None and result.outcome == "done":
        _score(result, arm, truth, cfg.force_n, width_m)
    return result


def _read_all(sensor: TactileSensor, estimator: TactileEstimator, cfg: ReorientConfig) -> TactileEstimate:
    if cfg.settle_s > 0:
        time.sleep(cfg.settle_s)
    try:
        return estimator.read(sensor, frames=cfg.frames, timeout_s=cfg.sensor_timeout_s)
    except SensorError as exc:
        raise _Abort("sensor_stale", f"tactile sensor: {exc}") from None


def _keep(result: GripResult, est: TactileEstimate, closed_loop: bool) -> None:
    if closed_loop:
        result.estimate, result.contact, result.position_mm = est.angle, est.contact, est.position_mm
    else:
        result.estimate = est.angle


def _centre(arm: Arm, gripper: Gripper, sensor: TactileSensor, estimator: TactileEstimator, width_m: float,
            cfg: ReorientConfig, spec: GripConfig, result: GripResult, est: TactileEstimate) -> TactileEstimate:
    """Move the pad centre onto the object's axis while the measured offset exceeds the tolerance."""
    while result.recentres < spec.max_recentres:
        shift_mm = _axis_offset_mm(est)
        if shift_mm is None or math.hypot(*shift_mm) <= spec.centre_tolerance_mm:
            return est
        result.recentres += 1
        try:
            base_T_hand = arm.state().base_T_hand
            gripper.open(width_m + 0.01)
        except ArmFault as exc:
            raise _Abort("arm_fault", f"arm state unavailable before centring: {exc}") from None
        except GripperError as exc:
            raise _Abort("grasp_failed", f"gripper error while opening to centre: {exc}") from None
        base_T_pad = base_T_hand @ hand_T_finger_pad(width_m)
        target = base_T_hand.copy()
        target[:3, 3] += base_T_pad[:3, :2] @ (np.asarray(shift_mm) * 1e-3)
        _move_hand(arm, target, cfg, "centring move")
        _close_at(gripper, width_m, result.commanded_force_n, cfg, "centred grasp")
        est = _read_all(sensor, estimator, cfg)
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
                 cfg: ReorientConfig, spec: GripConfig, result: GripResult, est: TactileEstimate) -> TactileEstimate:
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
        result.commanded_force_n = min(max(command * ratio, 0.5), GRIPPER_MAX_FORCE_N)
        _close_at(gripper, width_m, result.commanded_force_n, cfg, "force correction")
        est = _read_all(sensor, estimator, cfg)


def _close_at(gripper: Gripper, width_m: float, force_n: float, cfg: ReorientConfig, what: str) -> None:
    """Grasp at ``force_n`` (a held object keeps its place; the fingers' force changes)."""
    _close_on(gripper, width_m, dataclasses.replace(cfg, force_n=force_n), what)


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
