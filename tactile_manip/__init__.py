"""tactile_manip: tactile super-resolution for magnetic tactile sensors and its use in manipulation.

Importing the package is cheap: it pulls in numpy at most. Heavy or optional packages (torch,
onnxruntime, roboticstoolbox, franky, serial, trimesh, matplotlib) are imported where they are used.

The estimator users take is importable from here, and loaded (with the perception layer) when first named::

    from tactile_manip import TactileEstimator
    estimator = TactileEstimator.load()    # the shipped pose and contact models
"""

from typing import Any


from tactile_manip.errors import (
    ConfigError,
    DatasetError,
    MeshError,
    SimulationError,
    TactileManipError,
)
from tactile_manip.version import __version__

# names of the perception layer, imported when first used (module __getattr__): the package itself stays light
_LAZY = {
    "Estimator": "tactile_manip.perception.tactile_estimator",
    "TactileEstimate": "tactile_manip.perception.tactile_estimator",
    "TactileEstimator": "tactile_manip.perception.tactile_estimator",
}

__all__ = [
    "ConfigError",
    "DatasetError",
    "MeshError",
    "SimulationError",
    "Estimator",
    "TactileEstimate",
    "TactileEstimator",
    "TactileManipError",
    "__version__",
]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'tactile_manip' has no attribute {name!r}")

