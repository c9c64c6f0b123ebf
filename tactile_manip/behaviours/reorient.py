"""Grasp, estimate, reorient: the paper's in-hand reorientation behaviour (docs/design.md, Robot side).

The object is between the open fingers. The gripper closes to the force threshold, the tactile sensor is
read, the estimator gives the in-hand angle and its confidence, and the arm turns the hand (and with it the
object) about the pad normal through the contact by ``target - estimate``, so the object ends at the target
angle in the pad frame the grasp started in. Low confidence follows a policy: act anyway, re-grasp and read
again, or abstain. The estimator is a :class:`~tactile_manip.perception.tactile_estimator.TactileEstimator`;
where it holds a contact model of the sensor's board, the estimate step also reads the grip force from the
newest frame of the final grasp.

The behaviour receives its hardware (any :class:`~tactile_manip.robot.base.Arm`,
:class:`~tactile_manip.robot.base.Gripper`, :class:`~tactile_manip.sensors.base.TactileSensor`) and a
:class:`GroundTruth` that knows where the object really is (the kinematic twin in simulation; an operator or
a tracker on a real robot). Every fault it can meet becomes an outcome of the result, never an escape:
a missed grasp, a stale sensor, an IK failure, a safety refusal, an arm fault.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from tactile_manip.behaviours.skills import Abort, BehaviourConfig, close_on, grasp, read_pad, release
from tactile_manip.behaviours.task import Task, Trial, rounded
from tactile_manip.checks import check_finite_scalar
from tactile_manip.errors import ArmFault, IKError, SafetyLimitError, SensorError
from tactile_manip.perception.pose import wrap_axial
from tactile_manip.robot.base import Arm, Gripper
from tactile_manip.robot.frames import angle_in_plane, hand_T_finger_pad, rotate_pose_about
from tactile_manip.sensors.base import TactileSensor
from tactile_manip.types import AngleEstimate

if TYPE_CHECKING:
    from tactile_manip.perception.contact import ContactEstimator, ContactState
    from tactile_manip.perception.tactile_estimator import TactileEstimator

NO_TURN_RAD = 1e-6  # a correction smaller than this is not made (0.00006 deg)


class PhaseObserver(Protocol):
    """Told what the behaviour is doing, as it does it (a trial's frame recorder,
    :class:`~tactile_manip.trials.frames.TrialFrameStream`); it must not move anything."""

    def phase(self, name: str) -> None:
        """The behaviour enters ``name``: "grasp", "estimate", "turn" (the caller announces "release")."""

    def estimate(self, est: AngleEstimate) -> None:
        """An estimate was made (each read, re-grasps included)."""

    def contact(self, state: ContactState) -> None:
        """The contact model's state of the final grasp (its grip force); only with a contact model."""


class _Silent:
    def phase(self, name: str) -> None:
        pass

    def estimate(self, est: AngleEstimate) -> None:
        pass

    def contact(self, state: ContactState) -> None:
        pass


class GroundTruth(Protocol):
    """Where the object really is (for scoring only; the behaviour never uses it to act)."""

    def object_axis_base(self) -> np.ndarray | None:
        """Unit vector (3,) of the held object's principal axis in the base frame, or None when unknown."""


@dataclass
class ReorientResult:
    """What one run of the behaviour did (angles in rad, axial, in the pad frame at the first grasp)."""

    outcome: str
    detail: str = ""
    estimate: AngleEstimate | None = None
    action: str = "act"
    regrasps: int = 0
    correction_rad: float | None = None
    final_angle_rad: float | None = None
    error_rad: float | None = None
    grasp_width_m: float | None = None
    contact: ContactState | None = None  # the contact model's state at the estimate step (the grip force)
    timings_s: dict[str, float] = field(default_factory=dict)


def grasp_estimate_reorient(arm: Arm, gripper: Gripper, sensor: TactileSensor,
                            estimator: TactileEstimator, *, object_width_m: float,
                            target_angle_rad: float, config: BehaviourConfig | None = None,
                            truth: GroundTruth | None = None, pad_T: np.ndarray | None = None,
                            observer: PhaseObserver | None = None) -> ReorientResult:
    """Run the behaviour once on the object between the fingers (see the module docstring).

    Args:
        estimator: gives the angle; after the angle estimate, its contact model (where it has one) reads the
            newest frame of the final grasp into ``result.contact`` (the grip force and its sigma; None when no
            frame is fresh). An estimator of another board layout than the sensor's raises ValueError before
            anything moves.
        object_width_m: nominal width of the object across the fingers, m.
        target_angle_rad: commanded final angle of the object's axis in the pad frame at grasp.
        truth: scores the final angle when given (``final_angle_rad`` and ``error_rad`` stay None otherwise).
        pad_T: hand_T_pad of the sensor (default: the pad on the +y finger at the grasp width,
            :func:`~tactile_manip.robot.frames.hand_T_finger_pad`).
        observer: told each phase and estimate as they happen (see :class:`PhaseObserver`).

    The gripper is left closed on the object (the caller releases it); the arm stays where the correction
    left it, or where a fault stopped it.
    """
    cfg = config or BehaviourConfig()
    observer = observer or _Silent()
    contact = estimator.contact
    estimator.check_layout(sensor.layout)
    target = float(wrap_axial(check_finite_scalar("target_angle_rad", target_angle_rad)))
    result = ReorientResult(outcome="error")
    timings = result.timings_s
    t_start = time.perf_counter()
    try:
        observer.phase("grasp")
        base_T_hand, result.grasp_width_m = grasp(arm, gripper, object_width_m, cfg)
        base_T_pad = base_T_hand @ (hand_T_finger_pad(result.grasp_width_m) if pad_T is None else pad_T)
        timings["grasp"] = time.perf_counter() - t_start
        t0 = time.perf_counter()
        observer.phase("estimate")
        est = _estimate_with_policy(gripper, sensor, estimator, object_width_m, cfg, result, observer)
        result.estimate = est
        timings["estimate"] = time.perf_counter() - t0
        if contact is not None:
            t0 = time.perf_counter()
            result.contact = _grip_contact(sensor, contact, cfg, observer)
            timings["grip_force"] = time.perf_counter() - t0
        if result.action == "abstain":
            raise Abort("abstained", f"estimate below confidence {cfg.min_confidence:.2f}: "
                                      f"{est.reason or f'confidence {est.confidence:.2f}'}")
        result.correction_rad = float(wrap_axial(target - (est.angle_rad if est.defined else 0.0)))
        t0 = time.perf_counter()
        observer.phase("turn")
        result.correction_rad = _turn_about_pad_normal(arm, base_T_pad, est, result.correction_rad, cfg)
        timings["reorient"] = time.perf_counter() - t0
        result.outcome = "done"
    except Abort as stop:
        result.outcome, result.detail = stop.outcome, stop.detail
    finally:
        timings["total"] = time.perf_counter() - t_start
    if truth is not None and result.outcome == "done":
        axis = truth.object_axis_base()
        if axis is not None:
            result.final_angle_rad = float(wrap_axial(angle_in_plane(np.asarray(axis, float), base_T_pad)))
            result.error_rad = float(wrap_axial(result.final_angle_rad - target))
    return result


def _grip_contact(sensor: TactileSensor, contact: ContactEstimator, cfg: BehaviourConfig,
                  observer: PhaseObserver) -> ContactState | None:
    """The contact model's state of the newest frame (the last one the angle estimate read: the object is
    held at the final grasp), or None when the sensor has no frame within ``sensor_timeout_s`` or the model
    refuses the frame (NaN values): the grip force is logged, never acted on, so it never ends a trial."""
    try:
        reading = sensor.read_latest(max_age_s=cfg.sensor_timeout_s)
    except SensorError:
        return None
    contact.reset()  # one grasp, one estimate: no context from an earlier grasp
    try:
        state = contact.estimate(reading)
    except ValueError:
        return None
    observer.contact(state)
    return state


def _confident(est: AngleEstimate, cfg: BehaviourConfig) -> bool:
    return est.defined and est.confidence >= cfg.min_confidence


def _estimate_with_policy(gripper: Gripper, sensor: TactileSensor, estimator: TactileEstimator, width_m: float,
                          cfg: BehaviourConfig, result: ReorientResult, observer: PhaseObserver) -> AngleEstimate:
    est = read_pad(sensor, estimator, cfg, observer).angle
    if _confident(est, cfg) or cfg.low_confidence == "act":
        return est
    if cfg.low_confidence == "abstain":
        result.action = "abstain"
        return est
    best = est
    while result.regrasps < cfg.max_regrasps and not _confident(best, cfg):
        result.regrasps += 1
        result.action = "regrasp"
        observer.phase("grasp")
        release(gripper, width_m, "re-grasp")
        close_on(gripper, width_m, cfg, "re-grasp")
        observer.phase("estimate")
        est = read_pad(sensor, estimator, cfg, observer).angle
        if est.defined and (not best.defined or est.confidence > best.confidence):
            best = est
    return best


def _turn_about_pad_normal(arm: Arm, base_T_pad: np.ndarray, est: AngleEstimate, angle_rad: float,
                           cfg: BehaviourConfig) -> float:
    """Rotate the hand by ``angle_rad`` about the pad normal through the contact centroid; returns the turn made.

    A rod is axial: turning by ``angle_rad - sign(angle_rad) * pi`` aligns it just as well, so when the turn
    has no joint path (or the safety layer refuses it) the other way round is tried before giving up.
    """
    if abs(angle_rad) < NO_TURN_RAD:  # nothing to turn (a real arm's planner refuses a motion of zero length)
        return 0.0
    centroid_pad_m = np.array([est.centroid_mm[0] * 1e-3, est.centroid_mm[1] * 1e-3, 0.0, 1.0])
    point = (base_T_pad @ centroid_pad_m)[:3]
    turns = [angle_rad, angle_rad - math.copysign(math.pi, angle_rad)] if angle_rad != 0 else [0.0]
    failures: list[str] = []
    for turn in turns:
        try:
            start = arm.state().base_T_hand
            arm.move_cartesian(rotate_pose_about(start, base_T_pad[:3, 2], point, turn), speed_factor=cfg.speed_factor)
            return turn
        except (IKError, SafetyLimitError) as exc:  # the arm did not move: try the other way round
            failures.append(f"turn of {math.degrees(turn):+.1f} deg: {exc}")
            last = exc
        except ArmFault as exc:
            raise Abort("arm_fault", f"turn of {math.degrees(turn):+.1f} deg: {exc}") from None
    outcome = "safety_refused" if isinstance(last, SafetyLimitError) else "ik_failed"
    raise Abort(outcome, "; ".join(failures))


class Reorient(Task):
    """The paper's experiment as a trial: grasp, estimate the in-hand angle, turn the object to the scene's
    ``target_deg``; scored on the object's true final angle (``error_rad``: final - target)."""

    name = "reorient"
    title = "Reorientation trials"
    streams_frames = True

    def run(self, trial: Trial) -> ReorientResult:
        result = grasp_estimate_reorient(trial.arm, trial.gripper, trial.sensor, trial.estimator,
                                         object_width_m=trial.object_width_m,
                                         target_angle_rad=math.radians(self.scene.target_deg), config=self.behaviour,
                                         truth=trial.truth, observer=trial.observer)
        if trial.observer is not None:
            trial.observer.phase("release")  # the cell opens the gripper when the trial ends
        return result

    def failed(self, outcome: str, detail: str) -> ReorientResult:
        return ReorientResult(outcome=outcome, detail=detail)

    def record(self, result: ReorientResult) -> dict[str, Any]:
        est, grip = result.estimate, result.contact
        outcome, detail = result.outcome, result.detail
        if outcome == "done" and result.error_rad is None:
            outcome, detail = "unmeasured", "the final angle was not measured"
        return {"outcome": outcome, "detail": detail,
                "target_angle_rad": float(wrap_axial(math.radians(self.scene.target_deg))),
                "action": result.action, "regrasps": result.regrasps, "final_angle_rad": result.final_angle_rad,
                "error_rad": result.error_rad,
                "estimated_grip_force_n": rounded(None if grip is None else grip.force_n),
                "estimated_grip_force_sigma_n": rounded(None if grip is None else grip.force_sigma_n),
                "extra": {"grasp_width_m": result.grasp_width_m, "correction_rad": result.correction_rad,
                          "estimate_timings_s": dict(est.timings_s) if est is not None else {},
                          "commanded_force_n": float(self.behaviour.force_n)}}
