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
