"""Safety limits checked before any backend moves (numpy only).

:class:`SafeArm` wraps any :class:`~tactile_manip.robot.base.Arm` and refuses, with a
:class:`~tactile_manip.errors.SafetyLimitError` and without moving, a target outside :class:`SafetyLimits`:
joints too close to the arm's own limits, a TCP position outside the workspace box (base frame), a speed
factor above the allowed one, or a single Cartesian move that goes too far or turns too much. Wrap the real
arm in it by default; the limits are deliberately conservative and raised in the scene config.

The two pose helpers (:func:`check_rigid_transform`, :func:`pose_error`) live here because target checks
need them; the twin and the conformance check share them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_manip.checks import check_array, check_finite_scalar
from tactile_manip.errors import SafetyLimitError
from tactile_manip.robot.base import N_JOINTS, Arm, ArmState

_AXES = ("x", "y", "z")


def check_rigid_transform(name: str, a_T_b: object, *, tolerance: float = 1e-6) -> np.ndarray:
    """Return ``a_T_b`` as a float (4, 4) array after checking it is a proper rigid transform.

    Raises:
        ValueError: wrong shape, non-finite values, last row not [0, 0, 0, 1], rotation not orthonormal
            or with determinant -1 (a reflection), each beyond ``tolerance``.
    """
    t = check_array(name, a_T_b, shape=(4, 4))
    if np.abs(t[3] - [0.0, 0.0, 0.0, 1.0]).max() > tolerance:
        raise ValueError(f"{name}: last row must be [0, 0, 0, 1], got {t[3].tolist()}")
    r = t[:3, :3]
    ortho_err = float(np.abs(r.T @ r - np.eye(3)).max())
    if ortho_err > tolerance:
        raise ValueError(f"{name}: rotation is not orthonormal (max |R^T R - I| = {ortho_err:.2e}); "
                         "re-orthonormalise it (e.g. from a quaternion) before sending it")
    if np.linalg.det(r) < 0:
        raise ValueError(f"{name}: rotation has determinant -1 (a reflection, not a rotation)")
    return t


def rotation_angle_rad(a_R_b: np.ndarray, a_R_c: np.ndarray) -> float:
    """Angle (rad, in [0, pi]) of the rotation taking 3x3 rotation ``a_R_b`` to ``a_R_c``."""
    cos_angle = (float(np.trace(a_R_b.T @ a_R_c)) - 1.0) / 2.0
    return math.acos(min(1.0, max(-1.0, cos_angle)))


def pose_error(a_T_b: np.ndarray, a_T_c: np.ndarray) -> tuple[float, float]:
    """Distance (m) between the origins and angle (rad) between the orientations of two 4x4 poses."""
    position_m = float(np.linalg.norm(a_T_c[:3, 3] - a_T_b[:3, 3]))
    return position_m, rotation_angle_rad(a_T_b[:3, :3], a_T_c[:3, :3])


@dataclass(frozen=True)
class SafetyLimits:
    """Limits :class:`SafeArm` enforces on every target (defaults: a table-top FR3 cell, slow).

    Attributes:
        joint_margin_rad: keep joint targets this far inside the arm's own limits, rad.
        workspace_min_m: lower corner (x, y, z) of the allowed TCP box in the base frame, m.
        workspace_max_m: upper corner (x, y, z) of the allowed TCP box in the base frame, m.
        max_speed_factor: largest ``speed_factor`` a move may ask for, in (0, 1].
        max_cartesian_step_m: longest straight-line TCP travel of one Cartesian move, m.
        max_rotation_rad: largest TCP turn of one Cartesian move, rad, in (0, pi].
    """

    joint_margin_rad: float = 0.05  # rad
    workspace_min_m: tuple[float, float, float] = (0.2, -0.5, 0.05)  # m, base frame
    workspace_max_m: tuple[float, float, float] = (0.8, 0.5, 0.9)  # m, base frame
    max_speed_factor: float = 0.3  # fraction of the arm's velocity limits
    max_cartesian_step_m: float = 0.5  # m per move
    max_rotation_rad: float = math.pi  # rad per move

    def __post_init__(self) -> None:
        check_finite_scalar("joint_margin_rad", self.joint_margin_rad, low=0.0, high=0.5)
        lo = check_array("workspace_min_m", self.workspace_min_m, shape=(3,))
        hi = check_array("workspace_max_m", self.workspace_max_m, shape=(3,))
        for axis, a, b in zip(_AXES, lo, hi):
            if not a < b:
                raise ValueError(f"workspace_min_m.{axis} ({a}) must be < workspace_max_m.{axis} ({b})")
        check_finite_scalar("max_speed_factor", self.max_speed_factor, low=0.0, high=1.0, low_open=True)
        check_finite_scalar("max_cartesian_step_m", self.max_cartesian_step_m, low=0.0, low_open=True)
        check_finite_scalar("max_rotation_rad", self.max_rotation_rad, low=0.0, high=math.pi, low_open=True)


class SafeArm(Arm):
    """An :class:`Arm` that checks every target against :class:`SafetyLimits` before delegating.

    A refused target raises :class:`~tactile_manip.errors.SafetyLimitError` naming the joint or axis, the
    value and the limit; the wrapped arm is not asked to move. Everything else (connect, state, recover,
    and backend extras such as a twin's ``inject_fault``) goes straight to the wrapped arm.
    ``speed_factor=None`` keeps the wrapped arm's default, which is not checked here.
    """

    def __init__(self, arm: Arm, limits: SafetyLimits | None = None) -> None:
        self._arm = arm
        self.limits = limits if limits is not None else SafetyLimits()

    @property
    def arm(self) -> Arm:
        """The wrapped arm."""
        return self._arm

    def __getattr__(self, name: str) -> Any:
        # only called for attributes SafeArm lacks: backend extras (last_move_duration_s, inject_fault ...)
        if name.startswith("__") or name == "_arm":
            raise AttributeError(name)
        return getattr(self._arm, name)

    # --- delegated interface -------------------------------------------------------------------------
    def connect(self) -> None:
        self._arm.connect()

    def disconnect(self) -> None:
        self._arm.disconnect()

    @property
    def is_connected(self) -> bool:
        return self._arm.is_connected

    @property
    def q_min_rad(self) -> np.ndarray:
        return self._arm.q_min_rad

    @property
    def q_max_rad(self) -> np.ndarray:
        return self._arm.q_max_rad

    @property
    def dq_max_rad_s(self) -> np.ndarray:
        return self._arm.dq_max_rad_s

    @property
    def home_q_rad(self) -> np.ndarray:
        return self._arm.home_q_rad

    def state(self) -> ArmState:
        return self._arm.state()

    def recover(self) -> None:
        self._arm.recover()

    # --- checked moves -------------------------------------------------------------------------------
    def move_joints(self, q_rad: np.ndarray, *, speed_factor: float | None = None) -> None:
        """Refuse joint targets within ``joint_margin_rad`` of the arm's limits, then delegate."""
        q = check_array("q_rad", q_rad, shape=(N_JOINTS,))
        self._check_speed(speed_factor)
        self._check_joints(q)
        self._arm.move_joints(q, speed_factor=speed_factor)

    def move_cartesian(self, base_T_hand: np.ndarray, *, speed_factor: float | None = None) -> None:
        """Refuse a TCP target outside the workspace box or too far / too much turned from here, then delegate."""
        target = check_rigid_transform("base_T_hand", base_T_hand, tolerance=1e-5)
        self._check_speed(speed_factor)
        self._check_workspace(target[:3, 3])
        self._check_step(self._arm.state().base_T_hand, target)
        self._arm.move_cartesian(target, speed_factor=speed_factor)

    def _check_speed(self, speed_factor: float | None) -> None:
        if speed_factor is None:
            return
        sf = check_finite_scalar("speed_factor", speed_factor, low=0.0, low_open=True)
        if sf > self.limits.max_speed_factor:
            raise SafetyLimitError(f"speed_factor {sf} exceeds max_speed_factor {self.limits.max_speed_factor}; "
                                   "the arm did not move (raise the limit in the scene's safety config)")

    def _check_joints(self, q_rad: np.ndarray) -> None:
        margin = self.limits.joint_margin_rad
        lo = np.asarray(self._arm.q_min_rad) + margin
        hi = np.asarray(self._arm.q_max_rad) - margin
        for j in range(N_JOINTS):
            if not lo[j] <= q_rad[j] <= hi[j]:
                raise SafetyLimitError(
                    f"joint {j + 1} target {q_rad[j]:.4f} rad outside the safe range [{lo[j]:.4f}, {hi[j]:.4f}] "
                    f"rad (the arm's limits minus joint_margin_rad {margin}); the arm did not move")

    def _check_workspace(self, position_m: np.ndarray) -> None:
        lo, hi = self.limits.workspace_min_m, self.limits.workspace_max_m
        for i, axis in enumerate(_AXES):
            if not lo[i] <= position_m[i] <= hi[i]:
                raise SafetyLimitError(
                    f"TCP target {axis} = {position_m[i]:.4f} m outside the workspace [{lo[i]}, {hi[i]}] m "
                    "(base frame); the arm did not move")

    def _check_step(self, base_T_now: np.ndarray, base_T_target: np.ndarray) -> None:
        distance_m, angle_rad = pose_error(base_T_now, base_T_target)
        if distance_m > self.limits.max_cartesian_step_m:
            raise SafetyLimitError(
                f"Cartesian move of {distance_m:.4f} m exceeds max_cartesian_step_m "
                f"{self.limits.max_cartesian_step_m} m; split it into shorter moves. The arm did not move")
        if angle_rad > self.limits.max_rotation_rad + 1e-9:
            raise SafetyLimitError(
                f"Cartesian move turning {math.degrees(angle_rad):.2f} deg exceeds max_rotation_rad "
                f"{self.limits.max_rotation_rad:.4f} rad ({math.degrees(self.limits.max_rotation_rad):.1f} deg); "
                "split it into smaller turns. The arm did not move")
