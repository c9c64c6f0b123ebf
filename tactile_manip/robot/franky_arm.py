"""The franky-control backend: a real FR3 and Franka Hand over the FCI (docs/design.md, Robot side).

franky is imported on ``connect()`` only, so ``import tactile_manip.robot`` works without it; a missing franky
raises :class:`FrankyMissingError` naming the pip extra. The robot is reached only at the host the user put in
:class:`FrankyConfig` (no default address), with a low relative dynamics factor until they raise it.

Frames. ``base_T_hand`` is always the Franka Hand TCP (flange turned by ``hand_tcp_yaw_rad`` about its z axis
and shifted ``hand_tcp_offset_m`` along it: -45 deg and 0.1034 m for the stock hand), whatever end effector
is configured in Desk: the flange pose is recovered from franky's ``O_T_EE`` and ``F_T_EE``
(``base_T_flange = O_T_EE @ inv(F_T_EE)``) and the hand TCP is put on it; Cartesian targets are converted
back to the configured end-effector frame before franky sees them. With the stock Franka Hand in Desk (and
in franky-sim) that conversion is the identity and franky's straight line is the TCP's straight line.

Errors. A reflex or a control error that stopped a motion (``franky.ControlException``) and a lost connection
during a motion (``franky.NetworkException``) become :class:`~tactile_manip.errors.ArmFault` carrying franky's
text, and the arm refuses to move until ``recover()`` (franky's automatic error recovery). Commands the robot
refused (``CommandException``, ``InvalidOperationException``, ``RealtimeException``) become
:class:`~tactile_manip.errors.RobotError`; anything the gripper raises becomes
:class:`~tactile_manip.errors.GripperError`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from types import ModuleType
from typing import Any, ClassVar

import numpy as np

from tactile_manip.checks import check_array, check_finite_scalar
from tactile_manip.errors import ArmFault, GripperError, RobotError, RobotNotConnectedError, SafetyLimitError
from tactile_manip.extras import MissingExtraError, missing_message
from tactile_manip.robot.base import N_JOINTS, ArmState, GraspResult, Gripper, GripperState
from tactile_manip.robot.fr3 import FR3_HOME_Q_RAD, FR3Arm, check_fr3_configuration, fr3_joint_violation
from tactile_manip.robot.safety import check_rigid_transform

FRANKA_HAND_MAX_WIDTH_M = 0.08  # nominal opening of the Franka Hand before homing has measured it, m
FRANKA_HAND_MAX_FORCE_N = 140.0  # Franka Hand peak grasp force (70 N continuous), N


class FrankyMissingError(RobotError, MissingExtraError):
    """franky-control is not installed (a RobotError, and an ImportError like the other optional backends)."""


def import_franky() -> ModuleType:
    """Return the franky module, or raise :class:`FrankyMissingError` naming the extra that installs it."""
    try:
        import franky
    except ImportError as e:
        raise FrankyMissingError(missing_message("franky", "the franky backend (real FR3)")) from e
    return franky


def _thresholds(name: str, value: float | tuple[float, ...], n: int, unit: str) -> None:
    values = (value,) if isinstance(value, (int, float)) else value
    if not isinstance(values, tuple) or len(values) not in (1, n) or any(isinstance(v, bool) for v in values):
        raise ValueError(f"FrankyConfig.{name} must be one number or {n} numbers, {unit}, got {value!r}")
    for v in values:
        check_finite_scalar(f"FrankyConfig.{name}", v, low=0.0, low_open=True)


@dataclass(frozen=True)
class FrankyConfig:
    """How to reach a real FR3 (or franky-sim) through franky-control.

    ``host`` has no default on purpose: the robot is reached only at the address the user wrote down.
    """

    backend: ClassVar[str] = "franky"
    host: str                                   # FCI address of the robot's control unit, e.g. "172.16.0.2"
    relative_dynamics_factor: float = 0.05      # fraction of the FR3 velocity / acceleration / jerk limits, (0, 1]
    enforce_realtime: bool = True               # refuse to move without a PREEMPT_RT kernel (off for franky-sim)
    collision_torque_threshold_nm: float | tuple[float, ...] = 20.0  # joint torque reflex, Nm (one or 7 values)
    collision_force_threshold_n: float | tuple[float, ...] = 30.0    # TCP wrench reflex, N / Nm (one or 6 values)
    home_q_rad: tuple[float, ...] = FR3_HOME_Q_RAD  # configuration of home(), rad (the twin's home)
    hand_tcp_offset_m: float = 0.1034           # flange to hand TCP along the flange z axis, m (stock Franka Hand)
    hand_tcp_yaw_rad: float = -math.pi / 4      # hand TCP turn about the flange z axis, rad (stock Franka Hand)
    settle_tolerance_rad: float = 2e-4          # a move returns once every joint is this close to its held target, rad
    settle_velocity_rad_s: float = 2e-3         # ... or once every joint is slower than this (at rest off target), rad/s
    settle_timeout_s: float = 2.0               # ... or after this long at most, s

    def __post_init__(self) -> None:
        if not isinstance(self.host, str) or not self.host.strip() or any(c.isspace() for c in self.host):
            raise ValueError(f"FrankyConfig.host must be the robot's FCI address (e.g. '172.16.0.2'), "
                             f"got {self.host!r}")
        check_finite_scalar("FrankyConfig.relative_dynamics_factor", self.relative_dynamics_factor, low=0.0,
                            high=1.0, low_open=True)
        if not isinstance(self.enforce_realtime, bool):
            raise ValueError(f"FrankyConfig.enforce_realtime must be true or false, got {self.enforce_realtime!r}")
        _thresholds("collision_torque_threshold_nm", self.collision_torque_threshold_nm, 7, "Nm")
        _thresholds("collision_force_threshold_n", self.collision_force_threshold_n, 6, "N")
        check_fr3_configuration("FrankyConfig.home_q_rad", self.home_q_rad)
        check_finite_scalar("FrankyConfig.hand_tcp_offset_m", self.hand_tcp_offset_m, low=0.0, high=0.5)
        check_finite_scalar("FrankyConfig.hand_tcp_yaw_rad", self.hand_tcp_yaw_rad, low=-math.pi, high=math.pi)
        check_finite_scalar("FrankyConfig.settle_tolerance_rad", self.settle_tolerance_rad, low=0.0, high=0.1,
                            low_open=True)
        check_finite_scalar("FrankyConfig.settle_velocity_rad_s", self.settle_velocity_rad_s, low=0.0, high=0.1,
                            low_open=True)
        check_finite_scalar("FrankyConfig.settle_timeout_s", self.settle_timeout_s, low=0.0, high=60.0)

    @property
    def flange_T_hand(self) -> np.ndarray:
        """(4, 4) hand TCP in the flange frame."""
        c, s = math.cos(self.hand_tcp_yaw_rad), math.sin(self.hand_tcp_yaw_rad)
        t = np.eye(4)
        t[:2, :2] = [[c, -s], [s, c]]
        t[2, 3] = self.hand_tcp_offset_m
        return t


# --- franky <-> numpy ---------------------------------------------------------------------------------------

def matrix_from_affine(affine: Any) -> np.ndarray:
    """(4, 4) float array of a ``franky.Affine``."""
    return np.array(affine.matrix, dtype=np.float64).reshape(4, 4)


def affine_from_matrix(franky: ModuleType, a_T_b: np.ndarray) -> Any:
    """``franky.Affine`` of a (4, 4) transform, checked to be rigid before franky sees it (ValueError if not)."""
    return franky.Affine(check_rigid_transform("a_T_b", a_T_b, tolerance=1e-5))


def _franky_classes(franky: ModuleType, *names: str) -> tuple[type, ...]:
    # getattr: an older or stripped-down franky may lack some of them, and isinstance(e, ()) is simply False
    return tuple(c for c in (getattr(franky, n, None) for n in names) if isinstance(c, type))


def franky_errors(franky: ModuleType) -> tuple[type, ...]:
    """Every exception class franky raises (its ``Exception`` base and those that do not derive from it)."""
    return _franky_classes(franky, "Exception", "GripperException", "InvalidMotionTypeException",
                           "MotionReuseException", "ReactionRecursionException", "TorqueSignalTimeoutException")


def arm_error(franky: ModuleType, e: BaseException, *, action: str, host: str) -> RobotError:
    """Our exception for a franky exception ``e`` raised while doing ``action`` on the arm at ``host``."""
    text = str(e) or type(e).__name__
    if isinstance(e, _franky_classes(franky, "ControlException")):
        low = text.lower()
        kind = "communication" if "communication_constraints" in low else "reflex" if "reflex" in low else "control"
        return ArmFault(f"{action} stopped by the robot ({kind}): {text}. The arm stands where it stopped: call "
                        "recover() at the trial boundary before moving again", kind=kind)
    if isinstance(e, _franky_classes(franky, "NetworkException")):
        return ArmFault(f"{action}: lost the connection to the FR3 at {host}: {text}. Check the cable and that "
                        "FCI is still active in Desk, then disconnect() and connect() again", kind="communication")
    if isinstance(e, _franky_classes(franky, "RealtimeException")):
        return RobotError(f"{action} refused: {text}. Run on a PREEMPT_RT kernel with realtime rights, or set "
                          "FrankyConfig.enforce_realtime = false (simulator, or accepting jitter)")
    if isinstance(e, _franky_classes(franky, "CommandException", "InvalidOperationException")):
        return RobotError(f"{action} refused by the robot: {text}. Is FCI active, the arm unlocked and the "
                          "user stop released? After a reflex, call recover() first")
    return ArmFault(f"{action} failed: {type(e).__name__}: {text}; call recover() before moving again",
                    kind="fault")


class FrankyArm(FR3Arm):
    """A real FR3 (or franky-sim) through franky-control; see the module docstring for frames and errors.

    Every method but ``connect`` and the limit properties raises
    :class:`~tactile_manip.errors.RobotNotConnectedError` before ``connect()``. Joint targets outside the
    FR3 limits are refused with :class:`SafetyLimitError` before franky sees them (franky-sim does not enforce
    them). ``speed_factor`` multiplies the config's ``relative_dynamics_factor`` (franky's motion factor times
    its global factor); ``None`` means 1, i.e. the config's factor.
    """

    def __init__(self, config: FrankyConfig) -> None:
        self.config = config
        self._franky: ModuleType | None = None
        self._robot: Any = None
        self._fault = ""
        self._fault_kind = ""

    # --- connection ----------------------------------------------------------------------------------
    def connect(self) -> None:
        if self._robot is not None:
            return
        franky = import_franky()
        cfg = self.config
        realtime = franky.RealtimeConfig.Enforce if cfg.enforce_realtime else franky.RealtimeConfig.Ignore
        try:
            robot = franky.Robot(cfg.host, relative_dynamics_factor=cfg.relative_dynamics_factor,
                                 realtime_config=realtime)
        except franky_errors(franky) as e:
            raise RobotError(f"cannot connect to the FR3 at {cfg.host}: {e}. Is the robot on, the joints "
                             "unlocked, FCI activated in Desk, and this PC on the robot's network?") from e
        try:
            robot.set_collision_behavior(_seq(cfg.collision_torque_threshold_nm),
                                         _seq(cfg.collision_force_threshold_n))
        except franky_errors(franky) as e:
            robot = None  # franky closes the connection when the Robot object goes away
            raise arm_error(franky, e, action=f"configuring the FR3 at {cfg.host}", host=cfg.host) from e
        self._franky, self._robot = franky, robot
        self._fault = self._fault_kind = ""

    def disconnect(self) -> None:
        self._robot = None  # libfranka closes the connection when the Robot is destroyed
        self._franky = None

    @property
    def is_connected(self) -> bool:
        return self._robot is not None

    # --- state ---------------------------------------------------------------------------------------
    def state(self) -> ArmState:
        franky, robot = self._require_connected()
        try:
            s = robot.state
        except franky_errors(franky) as e:
            raise self._record(arm_error(franky, e, action="reading the arm state", host=self.config.host)) from e
        base_T_flange = matrix_from_affine(s.O_T_EE) @ np.linalg.inv(matrix_from_affine(s.F_T_EE))
        fault = self._fault or self._mode_fault(franky, s)
        return ArmState(q_rad=np.array(s.q, dtype=np.float64).reshape(N_JOINTS),
                        base_T_hand=base_T_flange @ self.config.flange_T_hand, faulted=bool(fault), fault=fault)

    @staticmethod
    def _mode_fault(franky: ModuleType, s: Any) -> str:
        modes = getattr(franky, "RobotMode", None)
        mode = getattr(s, "robot_mode", None)
        if modes is not None and mode == getattr(modes, "Reflex", object()):
            return f"robot in reflex mode: {getattr(s, 'current_errors', '')}"
        if modes is not None and mode == getattr(modes, "UserStopped", object()):
            return "user stop pressed: release it, then recover()"
        return ""

    # --- moves ---------------------------------------------------------------------------------------
    def move_joints(self, q_rad: np.ndarray, *, speed_factor: float | None = None) -> None:
        """Joint-space move (franky ``JointMotion``) to ``q_rad`` (7,), rad."""
        franky, robot = self._require_ready()
        q = check_array("q_rad", q_rad, shape=(N_JOINTS,))
        problem = fr3_joint_violation(q)
        if problem:
            raise SafetyLimitError(f"joint target refused: {problem}; the arm did not move")
        motion = franky.JointMotion(q.copy(), relative_dynamics_factor=_speed_factor(speed_factor))
        self._move(franky, robot, motion, action="joint move")

    def move_cartesian(self, base_T_hand: np.ndarray, *, speed_factor: float | None = None) -> None:
        """Straight-line move (franky ``CartesianMotion``, absolute, base frame) of the hand TCP."""
        franky, robot = self._require_ready()
        target = check_rigid_transform("base_T_hand", base_T_hand, tolerance=1e-5)
        sf = _speed_factor(speed_factor)
        try:
            flange_T_ee = matrix_from_affine(robot.state.F_T_EE)
        except franky_errors(franky) as e:
            raise self._record(arm_error(franky, e, action="reading the arm state", host=self.config.host)) from e
        base_T_ee = target @ np.linalg.inv(self.config.flange_T_hand) @ flange_T_ee
        motion = franky.CartesianMotion(affine_from_matrix(franky, base_T_ee), franky.ReferenceType.Absolute,
                                        relative_dynamics_factor=sf)
        self._move(franky, robot, motion, action="Cartesian move")

    def recover(self) -> None:
        """franky's automatic error recovery; clears the fault. Raises RobotError when the robot refuses."""
        franky, robot = self._require_connected()
        try:
            ok = robot.recover_from_errors()
        except franky_errors(franky) as e:
            raise arm_error(franky, e, action="error recovery", host=self.config.host) from e
        if ok is False:
            raise RobotError(f"automatic error recovery on the FR3 at {self.config.host} failed: release the user "
                             "stop, check Desk for the error, then call recover() again")
        self._fault = self._fault_kind = ""

    # --- internals -----------------------------------------------------------------------------------
    def _move(self, franky: ModuleType, robot: Any, motion: Any, *, action: str) -> None:
        try:
            robot.move(motion)
            self._settle(robot)
        except (*franky_errors(franky), RuntimeError) as e:  # its planner raises a plain RuntimeError
            raise self._record(arm_error(franky, e, action=action, host=self.config.host)) from e

    def _settle(self, robot: Any) -> None:
        # franky returns when the trajectory ends, but the joint controller may still trail it: franky-sim's
        # lags by up to ~20 mrad for ~0.5 s. The Arm contract says a move returns at the target, so wait until
        # the joints reach the held target, or stop moving (contact or friction can hold them off it), or
        # settle_timeout_s passes; the state then says where the arm is.
        cfg = self.config
        deadline = time.monotonic() + cfg.settle_timeout_s
        while True:
            s = robot.state
            error_rad = float(np.abs(np.asarray(s.q_d, dtype=np.float64) - np.asarray(s.q, dtype=np.float64)).max())
            speed_rad_s = float(np.abs(np.asarray(s.dq, dtype=np.float64)).max())
            if (error_rad <= cfg.settle_tolerance_rad or speed_rad_s <= cfg.settle_velocity_rad_s
                    or time.monotonic() >= deadline):
                return
            time.sleep(0.005)

    def _record(self, err: RobotError) -> RobotError:
        if isinstance(err, ArmFault):
            self._fault, self._fault_kind = str(err), err.kind
        return err

    def _require_connected(self) -> tuple[ModuleType, Any]:
        if self._robot is None or self._franky is None:
            raise RobotNotConnectedError(f"the FR3 at {self.config.host} is not connected: call connect() first")
        return self._franky, self._robot

    def _require_ready(self) -> tuple[ModuleType, Any]:
        franky, robot = self._require_connected()
        if self._fault:
            raise ArmFault(f"the arm is faulted ({self._fault}): call recover() before moving again",
                           kind="faulted")
        return franky, robot


def _speed_factor(speed_factor: float | None) -> float:
    if speed_factor is None:
        return 1.0
    return check_finite_scalar("speed_factor", speed_factor, low=0.0, high=1.0, low_open=True)


def _seq(value: float | tuple[float, ...]) -> float | list[float]:
    if isinstance(value, tuple):
        return float(value[0]) if len(value) == 1 else [float(v) for v in value]
    return float(value)


def gripper_error(e: BaseException, *, action: str, host: str) -> GripperError:
    """Our exception for anything franky raised while the Franka Hand at ``host`` was doing ``action``."""
    text = str(e) or type(e).__name__
    return GripperError(f"Franka Hand at {host}: {action} failed: {text}. Is the hand attached, powered and "
                        "homed (FrankyGripper.homing())?")


class FrankyGripper(Gripper):
    """The Franka Hand through franky-control (``franky.Gripper``), at the same host as the arm.

    A missed grasp is a :class:`GraspResult` with ``success=False``; a gripper that fails to move or answer
    raises :class:`GripperError` with franky's text.
    """

    def __init__(self, config: FrankyConfig) -> None:
        self.config = config
        self._franky: ModuleType | None = None
        self._gripper: Any = None

    def connect(self) -> None:
        if self._gripper is not None:
            return
        franky = import_franky()
        try:
            self._gripper = franky.Gripper(self.config.host)
        except franky_errors(franky) as e:
            raise GripperError(f"cannot connect to the Franka Hand at {self.config.host}: {e}. Is the hand "
                               "attached and enabled in Desk, and FCI active?") from e
        self._franky = franky

    def disconnect(self) -> None:
        self._gripper = None
        self._franky = None

    @property
    def is_connected(self) -> bool:
        return self._gripper is not None

    @property
    def max_width_m(self) -> float:
        """Widest opening measured by the last homing, m (the nominal 0.08 m before connect or homing)."""
        if self._gripper is None:
            return FRANKA_HAND_MAX_WIDTH_M
        width = float(self._call(lambda g: g.max_width, "reading the maximum width"))
        return width if width > 0.0 else FRANKA_HAND_MAX_WIDTH_M

    @property
    def max_force_n(self) -> float:
        return FRANKA_HAND_MAX_FORCE_N

    def state(self) -> GripperState:
        s = self._call(lambda g: g.state, "reading the state")
        return GripperState(width_m=float(s.width), is_grasped=bool(s.is_grasped))

    def homing(self) -> None:
        """Open fully and close to measure the maximum width (needed after changing the fingers)."""
        if not self._call(lambda g: g.homing(), "homing"):
            raise GripperError(f"Franka Hand at {self.config.host}: homing did not complete")

    def open(self, width_m: float | None = None, *, speed_m_s: float = 0.05) -> None:
        speed = check_finite_scalar("speed_m_s", speed_m_s, low=0.0, low_open=True)
        if width_m is None:
            ok = self._call(lambda g: g.open(speed), "opening")
            what = "open fully"
        else:
            width = check_finite_scalar("width_m", width_m, low=0.0, high=self.max_width_m)
            ok = self._call(lambda g: g.move(width, speed), f"moving to {width:.4f} m")
            what = f"reach {width:.4f} m"
        if not ok:
            raise GripperError(f"Franka Hand at {self.config.host}: did not {what} (is something in the way?)")

    def grasp(self, width_m: float, force_n: float, *, speed_m_s: float = 0.02, epsilon_inner_m: float = 0.005,
              epsilon_outer_m: float = 0.005) -> GraspResult:
        width = check_finite_scalar("width_m", width_m, low=0.0, high=self.max_width_m)
        force = check_finite_scalar("force_n", force_n, low=0.0, high=FRANKA_HAND_MAX_FORCE_N, low_open=True)
        speed = check_finite_scalar("speed_m_s", speed_m_s, low=0.0, low_open=True)
        inner = check_finite_scalar("epsilon_inner_m", epsilon_inner_m, low=0.0)
        outer = check_finite_scalar("epsilon_outer_m", epsilon_outer_m, low=0.0)
        t0 = time.monotonic()
        ok = bool(self._call(lambda g: g.grasp(width, speed, force, epsilon_inner=inner, epsilon_outer=outer),
                             f"grasping at {width:.4f} m with {force:.1f} N"))
        duration_s = time.monotonic() - t0
        return GraspResult(success=ok, width_m=self.state().width_m, force_n=force if ok else 0.0,
                           duration_s=duration_s)

    def _call(self, fn: Any, action: str) -> Any:
        if self._gripper is None or self._franky is None:
            raise RobotNotConnectedError(f"the Franka Hand at {self.config.host} is not connected: "
                                         "call connect() first")
        try:
            return fn(self._gripper)
        except franky_errors(self._franky) as e:
            raise gripper_error(e, action=action, host=self.config.host) from e
