"""Optional packages: which pip extra installs each one, and one clear error when one is missing.

Heavy or optional packages are imported where they are used (docs/design.md, Layers). :func:`require` imports
one and, when it is missing, raises :class:`MissingExtraError` naming the extra and the command that installs
it in a source checkout; :func:`missing_extra_message` turns any ImportError of such a package into that line.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from tactile_manip.errors import TactileManipError

# top-level module -> (distribution that provides it, the extra of pyproject.toml that installs it)
EXTRAS: dict[str, tuple[str, str]] = {
    "serial": ("pyserial", "serial"),
    "torch": ("torch", "train"),
    "onnx": ("onnx", "train"),
    "onnxruntime": ("onnxruntime", "onnx"),
    "roboticstoolbox": ("roboticstoolbox-python", "robot"),
    "spatialmath": ("roboticstoolbox-python", "robot"),
    "trimesh": ("trimesh", "mesh"),
    "cv2": ("opencv-python-headless", "camera"),
    "h5py": ("h5py", "hdf5"),
    "franky": ("franky-control", "franky"),
    "ray": ("ray", "ray"),
    "rerun": ("rerun-sdk", "viz"),
    "mcap": ("mcap", "mcap"),
    "pyarrow": ("pyarrow", "lerobot"),
    "pandas": ("pandas", "lerobot"),
    "sklearn": ("scikit-learn", "sklearn"),
    "zenoh": ("eclipse-zenoh", "ros2"),
    "foxglove": ("foxglove-sdk", "foxglove"),
}


class MissingExtraError(TactileManipError, ImportError):
    """An optional package is not installed; the message names the extra and the command that installs it."""


def install_command(extra: str) -> str:
    """The command that installs ``extra`` in a source checkout (torch first: pip's default is the CUDA build)."""
    if extra == "train":
        return 'pip install torch==2.13.0 && pip install -e ".[train]"'
    return f'pip install -e ".[{extra}]"'


def missing_message(module: str, purpose: str) -> str:
    """``"<purpose> needs <distribution> (extra 'x'): <install command>"`` for a top-level module of EXTRAS."""
    dist, extra = EXTRAS[module]
    return f"{purpose} needs {dist}, which is not installed (extra '{extra}'): {install_command(extra)}"


def require(module: str, purpose: str) -> ModuleType:
    """Import ``module`` (a key of EXTRAS, or a submodule of one) or raise :class:`MissingExtraError`.

    Args:
        module: e.g. ``"serial"`` or ``"serial.tools.list_ports"``.
        purpose: what needs it, for the message, e.g. ``"the serial sensor"``.
    """
    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise MissingExtraError(missing_message(module.split(".")[0], purpose)) from e


def missing_extra_message(error: BaseException) -> str | None:
    """One line for an ImportError of an optional package (in ``error`` or its causes), else None (a bug).

    A :class:`MissingExtraError` gives its own message; a bare ``ModuleNotFoundError`` of a module in EXTRAS
    gives the extra's install line.
    """
    seen = error
    while seen is not None:
        if isinstance(seen, MissingExtraError):
            return str(seen)
        name = (getattr(seen, "name", None) or "").split(".")[0]
        if isinstance(seen, ImportError) and name in EXTRAS:
            return missing_message(name, "this command")
        seen = seen.__cause__
    return None
