"""tactile_manip: tactile super-resolution for magnetic tactile sensors and its use in manipulation.

Importing the package is cheap: it pulls in numpy at most. Heavy or optional packages (torch,
onnxruntime, roboticstoolbox, franky, serial, trimesh, matplotlib) are imported where they are used.
"""

from tactile_manip.errors import (
    ConfigError,
    DatasetError,
    MeshError,
    SimulationError,
    TactileManipError,
)
from tactile_manip.version import __version__

__all__ = [
    "ConfigError",
    "DatasetError",
    "MeshError",
    "SimulationError",
    "TactileManipError",
    "__version__",
]
