"""The kinematic twin's world and Franka Hand: graspable objects, held rigidly, and the gripper (no dynamics).

An object presented between the open fingers is grasped when the fingers meet it (centred along the closing
axis, as the coupled fingers do), follows the hand rigidly while held, and stays where it is released.
:class:`TwinWorld` tells listeners (a simulated tactile sensor) when an object is grasped or released.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from tactile_manip.checks import check_finite_scalar
from tactile_manip.errors import GripperError, RobotNotConnectedError
from tactile_manip.robot.base import Arm, GraspResult, Gripper, GripperState
from tactile_manip.robot.safety import check_rigid_transform

if TYPE_CHECKING:
    from tactile_manip.robot.twin import KinematicArm

GRIPPER_MAX_WIDTH_M = 0.08  # Franka Hand stroke, m
GRIPPER_MAX_FORCE_N = 70.0  # Franka Hand continuous grasp force, N
GRIPPER_MAX_SPEED_M_S = 0.1  # Franka Hand finger speed (both fingers together), m/s
# an object's origin must lie inside this box around the TCP (half-extents x, y, z in the hand frame, m)
# to be between the fingers: the finger pads are about 20 mm square and open to +-40 mm along y.
FINGER_REGION_HALF_M = (0.02, GRIPPER_MAX_WIDTH_M / 2, 0.02)

GraspListener = Callable[["WorldObject", np.ndarray, float], None]
ReleaseListener = Callable[["WorldObject"], None]


@dataclass(eq=False)
class WorldObject:
    """A rigid object that can be presented to the hand and held (compared by identity).

    Attributes:
        name: label for logs.
        width_m: extent along the finger closing direction (hand y) where the fingers meet it, m.
        payload: anything the scene attaches (for example the simulator's indenter); the twin ignores it.
    """

    name: str
    width_m: float  # m
    payload: Any = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name must be a non-empty string, got {self.name!r}")
        check_finite_scalar("width_m", self.width_m, low=0.0, high=GRIPPER_MAX_WIDTH_M, low_open=True)


class TwinWorld:
    """Objects with poses in the base frame; at most one is held and then follows the hand rigidly.

    Listeners: ``on_grasp`` callbacks get ``(obj, hand_T_object, force_n)`` when the gripper closes on an
    object, ``on_release`` callbacks get ``(obj)`` when it lets go (the object stays where it was released).
    """

    def __init__(self, arm: Arm) -> None:
        self.arm = arm
        self.on_grasp: list[GraspListener] = []
        self.on_release: list[ReleaseListener] = []
        self._base_T_object: dict[WorldObject, np.ndarray] = {}
        self._held: WorldObject | None = None
        self._hand_T_held = np.eye(4)

    @property
    def objects(self) -> list[WorldObject]:
        """Objects in the world, in the order they were presented."""
        return list(self._base_T_object)

    @property
    def held(self) -> WorldObject | None:
        """The object the gripper holds, or None."""
        return self._held

    def present(self, obj: WorldObject, hand_T_object: np.ndarray) -> None:
        """Place ``obj`` at ``hand_T_object`` (4, 4) relative to the hand as it is now (between the open fingers)."""
        if not isinstance(obj, WorldObject):
            raise TypeError(f"obj must be a WorldObject, got {type(obj).__name__}")
        if obj in self._base_T_object:
            raise ValueError(f"{obj.name!r} is already in the world: remove() it before presenting it again")
        pose = check_rigid_transform("hand_T_object", hand_T_object)
        self._base_T_object[obj] = self._base_T_hand() @ pose

    def object_pose(self, obj: WorldObject) -> np.ndarray:
        """(4, 4) base_T_object now (moving with the hand while held)."""
        self._require_known(obj)
        if obj is self._held:
            return self._base_T_hand() @ self._hand_T_held
        return self._base_T_object[obj].copy()

    def remove(self, obj: WorldObject) -> None:
        """Take ``obj`` out of the world (released first if held)."""
        self._require_known(obj)
        if obj is self._held:
            self.release()
        del self._base_T_object[obj]

    def object_between_fingers(self) -> tuple[WorldObject, np.ndarray] | None:
        """The object whose origin is nearest the TCP inside :data:`FINGER_REGION_HALF_M`, with its hand_T_object."""
        hand_T_base = np.linalg.inv(self._base_T_hand())
        best: tuple[float, WorldObject, np.ndarray] | None = None
        for obj in self._base_T_object:
            hand_T_object = hand_T_base @ self.object_pose(obj)
            p = hand_T_object[:3, 3]
            if np.all(np.abs(p) <= FINGER_REGION_HALF_M) and (best is None or np.linalg.norm(p) < best[0]):
                best = (float(np.linalg.norm(p)), obj, hand_T_object)
        return None if best is None else (best[1], best[2])

    def hold(self, obj: WorldObject, hand_T_object: np.ndarray, force_n: float) -> None:
        """Attach ``obj`` to the hand at ``hand_T_object`` and tell the ``on_grasp`` listeners (gripper use)."""
        self._require_known(obj)
        if self._held is not None and self._held is not obj:
            raise ValueError(f"already holding {self._held.name!r}: release it before holding {obj.name!r}")
        self._held, self._hand_T_held = obj, np.array(hand_T_object, dtype=np.float64)
        for callback in list(self.on_grasp):
            callback(obj, self._hand_T_held.copy(), float(force_n))

    def release(self) -> None:
        """Let go of the held object where it is now and tell the ``on_release`` listeners (no-op if none)."""
        obj = self._held
        if obj is None:
            return
        self._base_T_object[obj] = self.object_pose(obj)
        self._held = None
        for callback in list(self.on_release):
            callback(obj)

    def _base_T_hand(self) -> np.ndarray:
        return self.arm.state().base_T_hand

    def _require_known(self, obj: WorldObject) -> None:
        if obj not in self._base_T_object:
            raise ValueError(f"{getattr(obj, 'name', obj)!r} is not in the world: present() it first")


class TwinGripper(Gripper):
    """A kinematic Franka Hand: the fingers stop on the object between them, which is then held.

    The coupled fingers centre a grasped object along the closing axis (its hand y offset becomes 0).
    A grasp that meets an object outside the width tolerance stops on it but fails (``success=False``,
    nothing held), as the real hand does; a grasp with nothing between the fingers closes fully.
    ``inject_fault()`` makes the next grasp raise :class:`GripperError`.
    """

    def __init__(self, arm: KinematicArm, world: TwinWorld, *, realtime: bool = False) -> None:
        if world.arm is not arm:
            raise ValueError("world must be built on the same arm as the gripper: TwinWorld(arm)")
        self.arm, self.world, self.realtime = arm, world, realtime
        self._width_m = GRIPPER_MAX_WIDTH_M
        self._connected = False
        self._armed_fault = ""
        self.last_duration_s = 0.0  # modelled duration of the last open / grasp, s

    def connect(self) -> None:
        self._connected = True

    def disconnect(self) -> None:
        self._connected = False

    @property
    def is_connected(self) -> bool:
        return self._connected

    @property
    def max_width_m(self) -> float:
        return GRIPPER_MAX_WIDTH_M

    @property
    def max_force_n(self) -> float:
        return GRIPPER_MAX_FORCE_N

    def state(self) -> GripperState:
        self._require_connected()
        return GripperState(width_m=self._width_m, is_grasped=self.world.held is not None)

    def inject_fault(self, message: str = "gripper communication error") -> None:
        """Make the next ``grasp`` raise :class:`GripperError` with ``message`` (one shot)."""
        self._armed_fault = str(message) or "gripper fault"

    def open(self, width_m: float | None = None, *, speed_m_s: float = 0.05) -> None:
        """Move the fingers to ``width_m`` (default fully open), releasing a held object narrower than it."""
        self._require_connected()
        width = GRIPPER_MAX_WIDTH_M if width_m is None else self._check_width(width_m)
        held = self.world.held
        if held is not None:
            if width <= held.width_m:
                raise GripperError(f"open to {width} m would not release {held.name!r} ({held.width_m} m wide): "
                                   "open wider (default: fully open)")
            self.world.release()
        self._move_fingers(width, speed_m_s)

    def grasp(self, width_m: float, force_n: float, *, speed_m_s: float = 0.02, epsilon_inner_m: float = 0.005,
              epsilon_outer_m: float = 0.005) -> GraspResult:
        self._require_connected()
        width = self._check_width(width_m)
        force = check_finite_scalar("force_n", force_n, low=0.0, high=GRIPPER_MAX_FORCE_N, low_open=True)
        eps_in = check_finite_scalar("epsilon_inner_m", epsilon_inner_m, low=0.0)
        eps_out = check_finite_scalar("epsilon_outer_m", epsilon_outer_m, low=0.0)
        if self._armed_fault:
            message, self._armed_fault = self._armed_fault, ""
            raise GripperError(f"grasp failed: {message} (injected); the fingers did not move. "
                               "Check the hand, then open() and retry")
        found = self.world.object_between_fingers()
        if found is None or found[0].width_m > self._width_m + 1e-9:
            duration_s = self._move_fingers(0.0, speed_m_s)
            return GraspResult(success=False, width_m=0.0, force_n=0.0, duration_s=duration_s)
        obj, hand_T_object = found
        duration_s = self._move_fingers(obj.width_m, speed_m_s)
        success = width - eps_in <= obj.width_m <= width + eps_out
        if success:  # a grasp of the object already held keeps its place and sets the new force
            centred = hand_T_object.copy()
            centred[1, 3] = 0.0  # the coupled fingers centre the object along the closing axis
            self.world.hold(obj, centred, force)
        elif not success:
            self.world.release()
        return GraspResult(success=success, width_m=obj.width_m, force_n=force, duration_s=duration_s)

    def _move_fingers(self, width_m: float, speed_m_s: float) -> float:
        speed = check_finite_scalar("speed_m_s", speed_m_s, low=0.0, high=GRIPPER_MAX_SPEED_M_S, low_open=True)
        duration_s = abs(self._width_m - width_m) / speed
        self._width_m = width_m
        self.last_duration_s = duration_s
        if self.realtime:
            time.sleep(duration_s)
        return duration_s

    def _check_width(self, width_m: float) -> float:
        return check_finite_scalar("width_m", width_m, low=0.0, high=GRIPPER_MAX_WIDTH_M)

    def _require_connected(self) -> None:
        if not self._connected:
            raise RobotNotConnectedError("the twin gripper is not connected: call connect() first")
