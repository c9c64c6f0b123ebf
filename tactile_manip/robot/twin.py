"""Kinematic FR3 twin: an ``Arm``, a ``Gripper`` and a tiny world of graspable objects (no dynamics).

The arm is roboticstoolbox-python's Panda model (its end frame is the Franka Hand TCP: flange, -45 deg about
z, 0.1034 m along z) with the FR3 joint limits substituted. Joint moves interpolate linearly; Cartesian moves
follow a straight line in position and a slerp in orientation, solved step by step with a warm-started
Levenberg-Marquardt IK. Motions are instantaneous unless ``realtime`` is set; their modelled duration (each
joint at most ``dq_max * speed_factor``, no acceleration phase) is logged in ``last_move_duration_s``.

A held object follows the hand rigidly; :class:`TwinWorld` tells listeners (a simulated tactile sensor) when
an object is grasped or released. roboticstoolbox is imported when an arm connects, never at import.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_manip.checks import check_array, check_finite_scalar
from tactile_manip.errors import ArmFault, IKError, RobotNotConnectedError, SafetyLimitError
from tactile_manip.extras import require
from tactile_manip.robot.base import N_JOINTS, ArmState
from tactile_manip.robot.fr3 import (FR3_DQ_MAX_RAD_S, FR3_HOME_Q_RAD, FR3_Q_MAX_RAD, FR3_Q_MIN_RAD,
                                     FR3Arm, check_fr3_configuration)
from tactile_manip.robot.frames import rotation_about
from tactile_manip.robot.safety import check_rigid_transform, pose_error


@dataclass(frozen=True)
class TwinArmConfig:
    """Settings of :class:`KinematicArm`.

    Attributes:
        home_q_rad: (7,) configuration of ``home()``, rad (inside the FR3 limits).
        speed_factor: default fraction of the joint velocity limits when a move passes none, in (0, 1].
        step_m: largest TCP translation between two IK steps of a Cartesian path, m.
        step_rad: largest TCP rotation between two IK steps, rad.
        max_joint_step_rad: a path step whose solution moves any joint more than this is refused, rad.
        ik_seed: seed of the perturbed warm starts tried when the plain warm start fails.
        ik_restarts: how many perturbed warm starts to try per step.
        ik_tolerance: IK residual bound, 0.5 |e|^2 with e the pose error (m and rad): 1e-12 ~ 1.4 um.
        reach_tolerance_m: the reached TCP position must be this close to the target, m.
        reach_tolerance_rad: the reached TCP orientation must be this close to the target, rad.
        realtime: sleep for the modelled duration of each move (off: moves return at once).
    """

    home_q_rad: tuple[float, ...] = FR3_HOME_Q_RAD  # rad
    speed_factor: float = 0.1  # fraction of dq_max, like a careful real robot
    step_m: float = 0.005  # m
    step_rad: float = 0.035  # rad (2 deg)
    max_joint_step_rad: float = 0.25  # rad
    ik_seed: int = 0
    ik_restarts: int = 4
    ik_tolerance: float = 1e-12  # 0.5 |e|^2, m and rad
    reach_tolerance_m: float = 1e-4  # m
    reach_tolerance_rad: float = 1e-3  # rad
    realtime: bool = False

    def __post_init__(self) -> None:
        check_fr3_configuration("home_q_rad", self.home_q_rad)
        check_finite_scalar("speed_factor", self.speed_factor, low=0.0, high=1.0, low_open=True)
        check_finite_scalar("step_m", self.step_m, low=0.0, high=0.1, low_open=True)
        check_finite_scalar("step_rad", self.step_rad, low=0.0, high=0.5, low_open=True)
        check_finite_scalar("max_joint_step_rad", self.max_joint_step_rad, low=0.0, high=math.pi, low_open=True)
        for name in ("ik_seed", "ik_restarts"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
        check_finite_scalar("ik_tolerance", self.ik_tolerance, low=0.0, high=1e-4, low_open=True)
        check_finite_scalar("reach_tolerance_m", self.reach_tolerance_m, low=0.0, low_open=True)
        check_finite_scalar("reach_tolerance_rad", self.reach_tolerance_rad, low=0.0, low_open=True)


@functools.lru_cache(maxsize=1)
def _fr3_kinematics() -> Any:
    """roboticstoolbox ETS of the Panda (flange + Franka Hand TCP) with the FR3 joint limits; built once."""
    rtb = require("roboticstoolbox", "the kinematic FR3 twin")
    panda = rtb.models.Panda()
    for link in panda.links:
        if link.isjoint:
            link.qlim = [FR3_Q_MIN_RAD[link.jindex], FR3_Q_MAX_RAD[link.jindex]]
    return panda.ets()


def interpolate_poses(base_T_start: np.ndarray, base_T_goal: np.ndarray, *, step_m: float,
                      step_rad: float) -> np.ndarray:
    """(N, 4, 4) poses from start (excluded) to goal (included): straight line in position, slerp in rotation.

    N is the smallest count keeping each step within ``step_m`` (m) and ``step_rad`` (rad), at least 1.
    """
    from scipy.spatial.transform import Rotation

    r0 = base_T_start[:3, :3]
    rotvec = Rotation.from_matrix(r0.T @ base_T_goal[:3, :3]).as_rotvec()  # start-frame axis * angle
    angle_rad = float(np.linalg.norm(rotvec))
    d_m = base_T_goal[:3, 3] - base_T_start[:3, 3]
    n = max(1, math.ceil(float(np.linalg.norm(d_m)) / step_m), math.ceil(angle_rad / step_rad))
    poses = np.tile(np.eye(4), (n, 1, 1))
    for i in range(1, n + 1):
        s = i / n
        rot = rotation_about(rotvec, s * angle_rad) if angle_rad > 1e-12 else np.eye(3)
        poses[i - 1, :3, :3] = r0 @ rot
        poses[i - 1, :3, 3] = base_T_start[:3, 3] + s * d_m
    poses[-1] = base_T_goal  # exact goal, no interpolation round-off
    return poses


class KinematicArm(FR3Arm):
    """The FR3 as pure kinematics: FK, stepped warm-started IK, limit and jump checks, fault injection.

    Moves are all-or-nothing: a Cartesian path is solved completely before the arm moves, and a refused move
    (:class:`IKError`, :class:`SafetyLimitError`) leaves it where it was. An injected fault stops the next
    move part-way and raises :class:`ArmFault`. Every method but ``connect`` raises
    :class:`RobotNotConnectedError` before ``connect()``. The arm starts at ``home_q_rad``.
    """

    def __init__(self, config: TwinArmConfig | None = None) -> None:
        self.config = config if config is not None else TwinArmConfig()
        self._q_rad = np.array(self.config.home_q_rad, dtype=np.float64)
        self._ets: Any = None
        self._connected = False
        self._fault = ""  # message of the current fault, "" when none
        self._fault_kind = ""
        self._armed_fault: tuple[str, float] | None = None
        self.last_move_duration_s = 0.0  # modelled duration of the last (possibly partial) move, s
        self.last_path_q_rad = self._q_rad[None].copy()  # (N, 7) configurations the last move went through

    # --- connection ----------------------------------------------------------------------------------
    def connect(self) -> None:
        if self._ets is None:
            self._ets = _fr3_kinematics()
        self._connected = True

    def disconnect(self) -> None:
        self._connected = False

    @property
    def is_connected(self) -> bool:
        return self._connected

    # --- state and kinematics ------------------------------------------------------------------------
    def state(self) -> ArmState:
        self._require_connected()
        return ArmState(q_rad=self._q_rad.copy(), base_T_hand=self.fk(self._q_rad),
                        faulted=bool(self._fault), fault=self._fault)

    def fk(self, q_rad: np.ndarray) -> np.ndarray:
        """(4, 4) TCP pose in the base frame at joint positions ``q_rad`` (7,), rad."""
        self._require_connected()
        q = check_array("q_rad", q_rad, shape=(N_JOINTS,))
        return np.array(self._ets.fkine(q).A, dtype=np.float64)

    # --- faults --------------------------------------------------------------------------------------
    def inject_fault(self, kind: str = "reflex", at_fraction: float = 0.5) -> None:
        """Arm a one-shot fault: the next move that starts stops at ``at_fraction`` of its path and raises
        :class:`ArmFault` (``kind``). A move refused before it starts does not use it up; ``recover()``
        disarms it."""
        if not isinstance(kind, str) or not kind:
            raise ValueError(f"kind must be a non-empty string, got {kind!r}")
        self._armed_fault = (kind, check_finite_scalar("at_fraction", at_fraction, low=0.0, high=1.0))

    def recover(self) -> None:
        """Clear the fault, and an injected fault no move has used yet (a fresh start at the trial boundary)."""
        self._require_connected()
        self._fault = self._fault_kind = ""
        self._armed_fault = None

    # --- moves ---------------------------------------------------------------------------------------
    def move_joints(self, q_rad: np.ndarray, *, speed_factor: float | None = None) -> None:
        """Linear joint-space move to ``q_rad`` (7,), rad. Raises SafetyLimitError outside the FR3 limits."""
        self._require_ready()
        q = check_array("q_rad", q_rad, shape=(N_JOINTS,))
        sf = self._speed_factor(speed_factor)
        problem = self._limit_problem(q)
        if problem:
            raise SafetyLimitError(f"joint target refused: {problem}; the arm did not move")
        self._execute(np.stack([self._q_rad, q]), sf)

    def move_cartesian(self, base_T_hand: np.ndarray, *, speed_factor: float | None = None) -> None:
        """Straight-line TCP move to ``base_T_hand`` (4, 4); raises IKError (arm unmoved) when a step fails."""
        self._require_ready()
        target = check_rigid_transform("base_T_hand", base_T_hand, tolerance=1e-5)
        sf = self._speed_factor(speed_factor)
        path_q = self.plan_cartesian(target)
        self._execute(path_q, sf)

    def plan_cartesian(self, base_T_hand: np.ndarray) -> np.ndarray:
        """(N + 1, 7) joint path (current configuration first) reaching ``base_T_hand``; nothing moves.

        Raises:
            IKError: a step has no solution inside the FR3 limits within ``max_joint_step_rad`` of the
                previous one, or the final configuration misses the target by more than the reach tolerance.
        """
        self._require_connected()
        target = check_rigid_transform("base_T_hand", base_T_hand, tolerance=1e-5)
        cfg = self.config
        poses = interpolate_poses(self.fk(self._q_rad), target, step_m=cfg.step_m, step_rad=cfg.step_rad)
        path = [self._q_rad.copy()]
        for i, pose in enumerate(poses):
            q, reason = self._solve_step(pose, path[-1], step_index=i)
            if q is None:
                raise IKError(f"move_cartesian: no IK solution at step {i + 1}/{len(poses)} ({reason}); "
                              f"target position {np.round(target[:3, 3], 4).tolist()} m; the arm did not move. "
                              "Choose a nearer target or move through an intermediate pose")
            path.append(q)
        self._check_reached(path[-1], target)
        return np.stack(path)

    # --- internals -----------------------------------------------------------------------------------
    def _solve_step(self, base_T_hand: np.ndarray, q_prev: np.ndarray, *,
                    step_index: int) -> tuple[np.ndarray | None, str]:
        """IK for one path pose warm-started at ``q_prev``; (q, "") or (None, why every start failed)."""
        rng = np.random.default_rng([self.config.ik_seed, step_index])
        starts = [q_prev] + [q_prev + rng.uniform(-0.05, 0.05, N_JOINTS) for _ in range(self.config.ik_restarts)]
        reason = ""
        for q0 in starts:
            # slimit=1: one search from q0 only (the solver's own restarts are not seeded, so not repeatable)
            sol = self._ets.ik_LM(base_T_hand, q0=q0, ilimit=60, slimit=1, tol=self.config.ik_tolerance,
                                  joint_limits=False)
            if not sol.success or sol.searches != 1:
                why = f"did not converge, residual {sol.residual:.1e}"
            else:
                q = _unwrap_near(np.asarray(sol.q, dtype=np.float64), q_prev)
                why = self._limit_problem(q) or self._jump_problem(q, q_prev)
                if not why:
                    return q, ""
            reason = reason or why  # the plain warm start's reason is the informative one
        return None, reason

    def _limit_problem(self, q_rad: np.ndarray) -> str:
        for j in range(N_JOINTS):
            if not FR3_Q_MIN_RAD[j] <= q_rad[j] <= FR3_Q_MAX_RAD[j]:
                return (f"joint {j + 1} = {q_rad[j]:.4f} rad outside the FR3 limits "
                        f"[{FR3_Q_MIN_RAD[j]}, {FR3_Q_MAX_RAD[j]}]")
        return ""

    def _jump_problem(self, q_rad: np.ndarray, q_prev: np.ndarray) -> str:
        dq = np.abs(q_rad - q_prev)
        j = int(np.argmax(dq))
        if dq[j] > self.config.max_joint_step_rad:
            return f"joint {j + 1} would jump {dq[j]:.3f} rad > max_joint_step_rad {self.config.max_joint_step_rad}"
        return ""

    def _check_reached(self, q_rad: np.ndarray, target: np.ndarray) -> None:
        position_m, angle_rad = pose_error(self.fk(q_rad), target)
        if position_m > self.config.reach_tolerance_m or angle_rad > self.config.reach_tolerance_rad:
            raise IKError(f"move_cartesian: the solved path ends {position_m * 1e3:.3f} mm / "
                          f"{math.degrees(angle_rad):.3f} deg from the target (tolerance "
                          f"{self.config.reach_tolerance_m * 1e3} mm / {self.config.reach_tolerance_rad} rad); "
                          "the arm did not move")

    def _execute(self, path_q: np.ndarray, speed_factor: float) -> None:
        """Commit a planned path (or the part before an injected fault), log its duration, maybe sleep."""
        segment_s = np.max(np.abs(np.diff(path_q, axis=0)) / (FR3_DQ_MAX_RAD_S * speed_factor), axis=1)
        fault, self._armed_fault = self._armed_fault, None
        if fault is not None:
            path_q, segment_s = _cut_path(path_q, segment_s, fault[1])
        self.last_path_q_rad = path_q.copy()
        self.last_move_duration_s = float(segment_s.sum())
        self._q_rad = path_q[-1].copy()
        if self.config.realtime:
            time.sleep(self.last_move_duration_s)
        if fault is not None:
            kind, fraction = fault
            self._fault, self._fault_kind = f"{kind} (injected) at {fraction:.0%} of the move", kind
            raise ArmFault(f"arm stopped by a {kind} fault at {fraction:.0%} of the move; call recover() "
                           "before moving again", kind=kind)

    def _speed_factor(self, speed_factor: float | None) -> float:
        if speed_factor is None:
            return self.config.speed_factor
        return check_finite_scalar("speed_factor", speed_factor, low=0.0, high=1.0, low_open=True)

    def _require_connected(self) -> None:
        if not self._connected:
            raise RobotNotConnectedError("the twin arm is not connected: call connect() first")

    def _require_ready(self) -> None:
        self._require_connected()
        if self._fault:
            raise ArmFault(f"the arm is faulted ({self._fault}): call recover() before moving again",
                           kind=self._fault_kind)


def _unwrap_near(q_rad: np.ndarray, q_ref_rad: np.ndarray) -> np.ndarray:
    """``q_rad`` shifted by whole turns to lie nearest ``q_ref_rad`` (the IK solver wraps angles to [-pi, pi])."""
    return q_rad + 2.0 * np.pi * np.round((q_ref_rad - q_rad) / (2.0 * np.pi))


def _cut_path(path_q: np.ndarray, segment_s: np.ndarray, fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """The first ``fraction`` of a piecewise-linear joint path (by path parameter) and its segment durations."""
    s = fraction * (len(path_q) - 1)
    i = min(int(math.floor(s)), len(path_q) - 2)
    frac = s - i
    q_stop = path_q[i] + frac * (path_q[i + 1] - path_q[i])
    return np.vstack([path_q[: i + 1], q_stop]), np.append(segment_s[:i], frac * segment_s[i])


# The world and the gripper live in twin_hand.py; re-exported here for one import site.
from tactile_manip.robot.twin_hand import (  # noqa: E402,F401 (re-exports)
    FINGER_REGION_HALF_M, GRIPPER_MAX_FORCE_N, GRIPPER_MAX_SPEED_M_S, GRIPPER_MAX_WIDTH_M, TwinGripper, TwinWorld,
    WorldObject)
