"""The models kept in the source checkout, found from the package, not the working folder.

    from tactile_manip.shipped import shipped_model
    model = load_reconstructor(shipped_model())            # models/supermag.onnx, the default
    contact = ContactEstimator(shipped_model("contact"))   # models/contact_supermag.onnx

The default, ``supermag`` (``models/supermag.onnx``), is the one model every shipped scene, task, example and
doc uses: the image graphs of the decoder trained on the paper's protocol and on 2-15 N presses of drawn
sensors, with an angle head inside (the contact's axis read straight from the reading, from which
:class:`~tactile_manip.perception.estimator.TactilePoseEstimator` takes the angle by default). ``models/``
holds it and the contact model of the same board only (``contact``: position, depth and force of a press).

Other models (a study's variants, your own) are files: every loader takes a path.

The models live beside the package in a source checkout (``pip install -e .``); a wheel does not carry them.
"""

from __future__ import annotations

from pathlib import Path

# name -> file name in models/
SHIPPED_MODELS: dict[str, str] = {
    "supermag": "supermag.onnx",  # the default: every scene, task, example and doc
    "contact": "contact_supermag.onnx",  # the contact model of the SuperMag board (ContactEstimator)
}
DEFAULT_MODEL = "supermag"
CONTACT_MODEL = "contact"


def _checkout() -> Path:
    """The source checkout's root (the folder above the package's own)."""
    return Path(__file__).resolve().parent.parent


def models_dir() -> Path:
    """The checkout's ``models/`` folder: the default model (and the contact model)."""
    return _checkout() / "models"


def shipped_model(name: str = DEFAULT_MODEL) -> Path:
    """Absolute path of a shipped model file: ``"supermag"`` (the default) or ``"contact"`` (the board's contact
    model), both in ``models/``.

    Raises:
        ValueError: ``name`` is not a shipped model.
        FileNotFoundError: the package runs outside a source checkout, so the model's folder is not beside it.
    """
    if name not in SHIPPED_MODELS:
        raise ValueError(f"unknown shipped model {name!r}: expected one of {', '.join(SHIPPED_MODELS)}")
    path = models_dir() / SHIPPED_MODELS[name]
    if not path.is_file():
        raise FileNotFoundError(f"shipped model not found: {path} (the {name} model is in the source checkout's "
                                "models/ folder: clone the repository and `pip install -e .` from it)")
    return path
