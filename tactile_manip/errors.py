"""Exception classes raised at the package's boundaries.

Expected outcomes (no contact, an undefined angle) are values, not exceptions. These classes are for
faults a caller has to act on; every message says what was wrong and what to do next.
"""

from __future__ import annotations


class TactileManipError(Exception):
    """Base class of every error this package raises on purpose."""


class ConfigError(TactileManipError, ValueError):
    """A configuration file or value is invalid; the message names the field, the value and what is allowed."""


class SimulationError(TactileManipError, RuntimeError):
    """The simulator could not produce a valid sample (for example the contact solver did not converge)."""


class MeshError(TactileManipError, ValueError):
    """A triangle mesh file could not be read or does not describe a usable indenter."""


class DatasetError(TactileManipError, ValueError):
    """A dataset file is missing, malformed, or from an incompatible format version."""


class SensorError(TactileManipError):
    """A tactile sensor (serial, simulated or replayed) cannot deliver what was asked."""


class SensorTimeoutError(SensorError, TimeoutError):
    """No frame, or no fresh enough frame, arrived in time; the message names the source and what to check."""


class SensorDisconnectedError(SensorError, ConnectionError):
    """The sensor is not connected (call ``connect()``), or its port could not be opened."""


class CalibrationError(SensorError, ValueError):
    """A baseline was refused (for example noise too high: something touched the pad while it was taken)."""


class ProtocolError(SensorError, ValueError):
    """Bytes or values that do not fit the MBTS wire protocol (docs/design.md, Wire protocol)."""


class RecordingError(SensorError, ValueError):
    """A sensor recording file is missing, is not a recording, or is from an incompatible format version."""


class RobotError(TactileManipError):
    """The arm or gripper cannot do what was asked; subclasses say whether it moved and how to recover."""


class RobotNotConnectedError(RobotError, ConnectionError):
    """An arm or gripper was used before ``connect()`` (or after ``disconnect()``)."""


class ArmFault(RobotError, RuntimeError):
    """The arm stopped on a fault mid-motion (a reflex, a communication or control error).

    The arm is stopped where the fault left it; call ``Arm.recover()`` (at the trial boundary) before moving
    again. ``kind`` names the fault (for example ``"reflex"`` or ``"communication"``).
    """

    def __init__(self, message: str, *, kind: str = "fault") -> None:
        super().__init__(message)
        self.kind = kind


class IKError(RobotError, ValueError):
    """No joint solution reaches a Cartesian target along the path (unreachable, a limit, or a joint jump).

    Raised before the arm moves: the arm is where it was.
    """


class SafetyLimitError(RobotError, ValueError):
    """A target outside the configured joint, workspace or speed limits was refused; the arm did not move."""


class GripperError(RobotError, RuntimeError):
    """The gripper failed to move or to report its state (not a missed grasp: that is a GraspResult)."""


class ClusterError(TactileManipError, RuntimeError):
    """A compute cluster cannot be used: unreachable, lacking our package, or a run's blocks are inconsistent."""
