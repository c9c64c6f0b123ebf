"""The skills tasks share: grasp, read the pad, move the hand, release; and what a trial-ending fault becomes.

Each skill takes the hardware it acts on (any :class:`~tactile_manip.robot.base.Arm`,
:class:`~tactile_manip.robot.base.Gripper`, :class:`~tactile_manip.sensors.base.TactileSensor`) and the
behaviour's :class:`BehaviourConfig`. A fault a trial can meet (a missed grasp, a stale sensor, an IK failure, a
safety refusal, an arm fault) is raised as :class:`Abort`, carrying the outcome the trial records; a task catches
it once, where it fills its result::

    try:
        base_T_hand, width_m = grasp(arm, gripper, object_width_m, cfg)
        estimate = read_pad(sensor, estimator, cfg)
        ...
        result.outcome = "done"
    except Abort as stop:
        result.outcome, result.detail = stop.outcome, stop.detail
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, Protocol

import numpy as np

from tactile_manip.checks import check_choice, check_finite_scalar
from tactile_manip.errors import ArmFault, GripperError, IKError, SafetyLimitError, SensorError
from tactile_manip.robot.base import Arm, Gripper
from tactile_manip.sensors.base import TactileSensor

if TYPE_CHECKING:
    from tactile_manip.perception.tactile_estimator import TactileEstimate, TactileEstimator

POLICIES = ("act", "regrasp", "abstain")
RELEASE_MARGIN_M = 0.01  # a release opens the fingers this much wider than the object


@dataclass(frozen=True)
class BehaviourConfig:
    """How a behaviour grasps, reads and moves (a scene's ``[behaviour]`` table; every task reads it).

    Attributes:
        force_n: grasp force threshold, N (the paper's gripper threshold: 10 N).
        width_tolerance_m: accepted deviation of the grasp width from the object's nominal width, m.
        settle_s: wait after the grasp before the frames are read (the skin and the filter settle), s.
        frames: consecutive frames averaged for one estimate (8 ms each at 125 Hz).
        sensor_timeout_s: a frame later than this aborts the trial as a stale sensor, s.
        min_confidence: estimates below this confidence (or undefined ones) trigger the policy.
        low_confidence: "act" (turn anyway; an undefined angle then counts as 0), "regrasp" (open, close
            again and re-read, up to ``max_regrasps`` times, then act on the best estimate) or "abstain".
        max_regrasps: re-grasps allowed by the "regrasp" policy.
        speed_factor: arm speed factor for the moves (None: the backend's default).
    """

    force_n: float = 10.0
    width_tolerance_m: float = 0.004
    settle_s: float = 0.04
    frames: int = 4
    sensor_timeout_s: float = 0.1
    min_confidence: float = 0.3
    low_confidence: Literal["act", "regrasp", "abstain"] = "regrasp"
    max_regrasps: int = 1
    speed_factor: float | None = None

    def __post_init__(self) -> None:
        check_finite_scalar("force_n", self.force_n, low=0.0, low_open=True, high=140.0)
        check_finite_scalar("width_tolerance_m", self.width_tolerance_m, low=0.0, high=0.08)
        check_finite_scalar("settle_s", self.settle_s, low=0.0, high=10.0)
        check_finite_scalar("sensor_timeout_s", self.sensor_timeout_s, low=0.0, low_open=True)
        check_finite_scalar("min_confidence", self.min_confidence, low=0.0, high=1.0)
        check_choice("low_confidence", self.low_confidence, POLICIES)
        if isinstance(self.frames, bool) or not isinstance(self.frames, int) or self.frames < 1:
            raise ValueError(f"frames must be a positive integer, got {self.frames!r}")
        if isinstance(self.max_regrasps, bool) or not isinstance(self.max_regrasps, int) or self.max_regrasps < 0:
            raise ValueError(f"max_regrasps must be a non-negative integer, got {self.max_regrasps!r}")


class Abort(Exception):
    """A trial-ending outcome met by a skill (``outcome`` is one of the trial log's outcomes, ``detail`` says
    what happened). A task catches it and records it; it never escapes a task."""

    def __init__(self, outcome: str, detail: str) -> None:
        super().__init__(detail)
        self.outcome, self.detail = outcome, detail


class EstimateObserver(Protocol):
    """Told each estimate a skill reads (a trial's frame recorder); it must not move anything."""

    def estimate(self, est: Any) -> None:
        """An angle estimate was read."""


def close_on(gripper: Gripper, width_m: float, cfg: BehaviourConfig, what: str, *,
             force_n: float | None = None) -> float:
    """Close on the object at ``force_n`` (default ``cfg.force_n``); returns the grasp width, m.

    Raises:
        Abort: "grasp_failed" when the gripper fails or stops outside ``width_m`` +- ``cfg.width_tolerance_m``.
    """
    force = cfg.force_n if force_n is None else force_n
    try:
        grasp_ = gripper.grasp(width_m, force, epsilon_inner_m=cfg.width_tolerance_m,
                               epsilon_outer_m=cfg.width_tolerance_m)
    except GripperError as exc:
        raise Abort("grasp_failed", f"gripper error during the {what}: {exc}") from None
    if not grasp_.success:
        raise Abort("grasp_failed", f"{what}: the gripper stopped at {grasp_.width_m * 1e3:.1f} mm, object "
                                    f"{width_m * 1e3:.1f} +- {cfg.width_tolerance_m * 1e3:.1f} mm")
    return grasp_.width_m


def grasp(arm: Arm, gripper: Gripper, width_m: float, cfg: BehaviourConfig) -> tuple[np.ndarray, float]:
    """Close on the object between the fingers; returns base_T_hand (4, 4) at the grasp and the grasp width, m.

    Raises:
        Abort: "grasp_failed" (see :func:`close_on`) or "arm_fault" (the arm's state is unavailable).
    """
    width = close_on(gripper, width_m, cfg, "grasp")
    try:
        return arm.state().base_T_hand, width
    except ArmFault as exc:
        raise Abort("arm_fault", f"arm state unavailable after the grasp: {exc}") from None


def release(gripper: Gripper, width_m: float, what: str = "release") -> None:
    """Open the fingers ``RELEASE_MARGIN_M`` wider than ``width_m`` (the object stays where it is).

    Raises:
        Abort: "grasp_failed" when the gripper fails.
    """
    try:
        gripper.open(width_m + RELEASE_MARGIN_M)
    except GripperError as exc:
        raise Abort("grasp_failed", f"gripper error during the {what}: {exc}") from None


def move_hand(arm: Arm, base_T_hand: np.ndarray, cfg: BehaviourConfig, what: str) -> None:
    """A Cartesian move of the hand to ``base_T_hand`` (4, 4) at ``cfg.speed_factor``.

    Raises:
        Abort: "ik_failed", "safety_refused" or "arm_fault", naming ``what``.
    """
    try:
        arm.move_cartesian(base_T_hand, speed_factor=cfg.speed_factor)
    except IKError as exc:
        raise Abort("ik_failed", f"{what}: {exc}") from None
    except SafetyLimitError as exc:
        raise Abort("safety_refused", f"{what}: {exc}") from None
    except ArmFault as exc:
        raise Abort("arm_fault", f"{what}: {exc}") from None


def approach(arm: Arm, shift_base_m: np.ndarray, cfg: BehaviourConfig, what: str = "approach") -> None:
    """Translate the hand by ``shift_base_m`` (3,), m, in the base frame, keeping its orientation.

    Raises:
        Abort: as :func:`move_hand`; "arm_fault" when the arm's state is unavailable.
    """
    try:
        target = arm.state().base_T_hand.copy()
    except ArmFault as exc:
        raise Abort("arm_fault", f"{what}: arm state unavailable: {exc}") from None
    target[:3, 3] += np.asarray(shift_base_m, float)
    move_hand(arm, target, cfg, what)


def read_pad(sensor: TactileSensor, estimator: TactileEstimator, cfg: BehaviourConfig,
             observer: EstimateObserver | None = None) -> TactileEstimate:
    """Wait ``cfg.settle_s``, then read ``cfg.frames`` fresh frames through ``estimator``; returns its
    :class:`~tactile_manip.perception.tactile_estimator.TactileEstimate` (``angle``; ``contact`` and
    ``position_mm`` where the estimator has a contact model, else None), after telling ``observer`` the angle.

    Raises:
        Abort: "sensor_stale" when the sensor has no fresh frame within ``cfg.sensor_timeout_s``.
    """
    if cfg.settle_s > 0:
        time.sleep(cfg.settle_s)
    try:
        est = estimator.read(sensor, frames=cfg.frames, timeout_s=cfg.sensor_timeout_s)
    except SensorError as exc:
        raise Abort("sensor_stale", f"tactile sensor: {exc}") from None
    if observer is not None:
        observer.estimate(est.angle)
    return est
