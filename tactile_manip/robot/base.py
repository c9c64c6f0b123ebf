"""The ``Arm`` and ``Gripper`` interfaces (docs/design.md, Robot side) that every robot backend implements.

Backends: :mod:`tactile_manip.robot.twin` (kinematic FR3 twin on roboticstoolbox-python) and
:mod:`tactile_manip.robot.franky_arm` (a real FR3 through franky-control). Behaviours receive an ``Arm`` and a
``Gripper`` and never build them, so the same behaviour runs on both.

Conventions: SI units (m, rad, s, N); poses are 4x4 homogeneous arrays named ``a_T_b`` (frame b expressed in
frame a), ``base`` is the robot base frame and ``hand`` the Franka Hand's TCP frame (z along the approach
direction, fingers closing along y). Moves are blocking and return when the arm is at the target.

Errors: :class:`~tactile_manip.errors.IKError` (no solution, the arm did not move),
:class:`~tactile_manip.errors.SafetyLimitError` (refused, the arm did not move),
:class:`~tactile_manip.errors.ArmFault` (stopped mid-motion; ``recover()`` before moving again).
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from types import TracebackType

import numpy as np

N_JOINTS = 7


@dataclass(frozen=True, eq=False)
class ArmState:
    """Where the arm is.

    Attributes:
        q_rad: (7,) joint positions, rad.
        base_T_hand: (4, 4) TCP pose in the base frame, m.
        faulted: True after an :class:`~tactile_manip.errors.ArmFault` until ``recover()``.
        fault: the last fault's message ("" when none).
    """

    q_rad: np.ndarray
    base_T_hand: np.ndarray
    faulted: bool = False
    fault: str = ""


@dataclass(frozen=True)
class GripperState:
    """Finger opening and whether something is held (``is_grasped``: closed on an object within tolerance)."""

    width_m: float
    is_grasped: bool


@dataclass(frozen=True)
class GraspResult:
    """Outcome of :meth:`Gripper.grasp` (a missed grasp is a value, not an exception).

    Attributes:
        success: the fingers stopped on an object at the force threshold with a width inside
            [width_m - epsilon_inner_m, width_m + epsilon_outer_m].
        width_m: finger opening where they stopped, m.
        force_n: grasp force applied, N (0 when nothing was grasped).
        duration_s: time the grasp took, s.
    """

    success: bool
    width_m: float
    force_n: float
    duration_s: float


class _Connectable(abc.ABC):
    """connect / disconnect and the context manager, shared by arms and grippers."""

    @abc.abstractmethod
    def connect(self) -> None:
        """Open the connection (idempotent)."""

    @abc.abstractmethod
    def disconnect(self) -> None:
        """Close the connection (idempotent; never raises for an already closed backend)."""

    @property
    @abc.abstractmethod
    def is_connected(self) -> bool:
        """Whether ``connect()`` has succeeded and ``disconnect()`` has not been called since."""

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.disconnect()


class Arm(_Connectable):
    """A 7-joint arm with a TCP frame; blocking joint and Cartesian moves."""

    @property
    @abc.abstractmethod
    def q_min_rad(self) -> np.ndarray:
        """(7,) lower joint limits, rad."""

    @property
    @abc.abstractmethod
    def q_max_rad(self) -> np.ndarray:
        """(7,) upper joint limits, rad."""

    @property
    @abc.abstractmethod
    def dq_max_rad_s(self) -> np.ndarray:
        """(7,) joint velocity limits, rad/s."""

    @property
    @abc.abstractmethod
    def home_q_rad(self) -> np.ndarray:
        """(7,) the configuration ``home()`` moves to, rad."""

    @abc.abstractmethod
    def state(self) -> ArmState:
        """Current joint positions and TCP pose."""

    @abc.abstractmethod
    def move_joints(self, q_rad: np.ndarray, *, speed_factor: float | None = None) -> None:
        """Move to joint positions ``q_rad`` (7,), rad. ``speed_factor`` in (0, 1] scales the backend's default."""

    @abc.abstractmethod
    def move_cartesian(self, base_T_hand: np.ndarray, *, speed_factor: float | None = None) -> None:
        """Move the TCP along a straight line (and a slerp of orientation) to ``base_T_hand`` (4, 4)."""

    @abc.abstractmethod
    def recover(self) -> None:
        """Clear a fault so the arm can move again (call at the trial boundary, not mid-trial)."""

    def home(self, *, speed_factor: float | None = None) -> None:
        """Move to :attr:`home_q_rad`."""
        self.move_joints(self.home_q_rad, speed_factor=speed_factor)


class Gripper(_Connectable):
    """A parallel gripper (the Franka Hand): fingers close along the hand's y axis."""

    @property
    @abc.abstractmethod
    def max_width_m(self) -> float:
        """Widest opening, m."""

    @property
    @abc.abstractmethod
    def max_force_n(self) -> float:
        """The largest grasp force :meth:`grasp` accepts, N (a force servo clips its command to it)."""

    @abc.abstractmethod
    def state(self) -> GripperState:
        """Current opening and grasp flag."""

    @abc.abstractmethod
    def open(self, width_m: float | None = None, *, speed_m_s: float = 0.05) -> None:
        """Open to ``width_m`` (default: fully open)."""

    @abc.abstractmethod
    def grasp(self, width_m: float, force_n: float, *, speed_m_s: float = 0.02, epsilon_inner_m: float = 0.005,
              epsilon_outer_m: float = 0.005) -> GraspResult:
        """Close until the fingers press an object with ``force_n``; success when the final width is within
        [width_m - epsilon_inner_m, width_m + epsilon_outer_m]."""
