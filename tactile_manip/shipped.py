"""The models shipped in the source checkout's ``models/`` folder, found from the package, not the working folder.

    from tactile_manip.shipped import shipped_model
    model = load_reconstructor(shipped_model())            # models/supermag.onnx, the default
    fast = load_reconstructor(shipped_model("fast"))       # a reference model of the bench

The default, ``supermag`` (``models/supermag.onnx``), is the one model every shipped scene, task, example and
doc uses: the image graphs of the decoder trained on the paper's protocol and on 2-15 N presses of drawn
sensors, with an angle head inside (the contact's axis read straight from the reading, from which
:class:`~tactile_manip.perception.estimator.TactilePoseEstimator` takes the angle by default). The others are kept only as
references for ``tactile-manip bench`` and the published results: ``fast`` (the same decoder trained on the
paper's protocol only), ``robust`` (the default's image graphs without the angle head) and ``compact`` (the
larger decoder shipped before them, the accuracy reference).

The models live beside the package in a source checkout (``pip install -e .``); a wheel does not carry them.
"""

from __future__ import annotations

from pathlib import Path

# name -> file in models/
SHIPPED_MODELS: dict[str, str] = {
    "supermag": "supermag.onnx",  # the default: every scene, task, example and doc
    "fast": "supermag_fast.onnx",  # bench reference: the decoder trained on the paper's protocol only
    "robust": "supermag_robust.onnx",  # bench reference: the default's image graphs, without its angle head
    "compact": "supermag_compact.onnx",  # bench reference: the larger decoder, the accuracy reference
}
DEFAULT_MODEL = "supermag"
REFERENCE_MODELS: tuple[str, ...] = ("fast", "robust", "compact")  # kept for the bench, not for tasks


def models_dir() -> Path:
    """The checkout's ``models/`` folder (the folder above the package's own)."""
    return Path(__file__).resolve().parent.parent / "models"


def shipped_model(name: str = DEFAULT_MODEL) -> Path:
    """Absolute path of a shipped model file: ``"supermag"`` (the default), or a bench reference (``"fast"``,
    ``"robust"``, ``"compact"``).

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
