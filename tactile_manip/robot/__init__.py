"""Robot side (docs/design.md, Robot side): the ``Arm`` and ``Gripper`` interfaces and their backends.

Modules:
    base: the ``Arm`` and ``Gripper`` interfaces, ``ArmState``, ``GripperState``, ``GraspResult``.
    frames: rigid transforms and the tactile pad's frame on the Franka Hand (numpy only).
    safety: ``SafetyLimits`` and ``SafeArm``, a wrapper refusing targets outside joint, workspace and speed
        limits before any backend sees them (numpy only).
    twin: the kinematic FR3 twin (``KinematicArm``, ``TwinGripper``, ``TwinWorld``) on roboticstoolbox-python
        (imported when a twin connects; install the ``robot`` extra).
    conformance: ``run_conformance``, the behaviour check every Arm / Gripper backend must pass.

Importing this package pulls in numpy only; roboticstoolbox and franky are imported by the backends that use
them.
"""

from tactile_manip.errors import ArmFault, GripperError, IKError, RobotError, SafetyLimitError
from tactile_manip.robot.base import Arm, ArmState, GraspResult, Gripper, GripperState

__all__ = [
    "Arm",
    "ArmFault",
    "ArmState",
    "GraspResult",
    "Gripper",
    "GripperError",
    "GripperState",
    "IKError",
    "RobotError",
    "SafetyLimitError",
]
