"""The models shipped in the source checkout's ``models/`` folder, found from the package, not the working folder.

    from tactile_manip.shipped import shipped_model
    model = load_reconstructor(shipped_model())            # models/supermag_fast.onnx, the default
    robust = load_reconstructor(shipped_model("robust"))   # the model of the 2-15 N, drawn-sensor scene

The models live beside the package in a source checkout (``pip install -e .``); a wheel does not carry them.
"""

from __future__ import annotations

from pathlib import Path

# name -> file in models/
SHIPPED_MODELS: dict[str, str] = {
    "fast": "supermag_fast.onnx",  # the default: every scene but the robust one, the docs, the examples
    "robust": "supermag_robust.onnx",  # the same decoder trained on 2-15 N presses of drawn sensors too
    "compact": "supermag_compact.onnx",  # the previous default, kept as the accuracy reference
}
DEFAULT_MODEL = "fast"


def models_dir() -> Path:
    """The checkout's ``models/`` folder (the folder above the package's own)."""
    return Path(__file__).resolve().parent.parent / "models"


def shipped_model(name: str = DEFAULT_MODEL) -> Path:
    """Absolute path of a shipped model file (``"fast"``, ``"robust"`` or ``"compact"``).

    Raises:
        ValueError: ``name`` is not a shipped model.
        FileNotFoundError: the package runs outside a source checkout, so no ``models/`` folder is beside it.
    """
    if name not in SHIPPED_MODELS:
        raise ValueError(f"unknown shipped model {name!r}: expected one of {', '.join(SHIPPED_MODELS)}")
    path = models_dir() / SHIPPED_MODELS[name]
    if not path.is_file():
        raise FileNotFoundError(f"shipped model not found: {path} (the models are in the source checkout's "
                                "models/ folder: clone the repository and `pip install -e .` from it)")
    return path
