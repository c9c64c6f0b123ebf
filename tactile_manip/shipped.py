"""The models kept in the source checkout, found from the package, not the working folder.

    from tactile_manip.shipped import shipped_model
    model = load_reconstructor(shipped_model())            # models/supermag.onnx, the default
    contact = ContactEstimator(shipped_model("contact"))   # models/contact_supermag.onnx

Every loader (:func:`~tactile_manip.perception.reconstruct.load_reconstructor`,
:class:`~tactile_manip.perception.contact.ContactEstimator`, ``TactileEstimator.load``, the scenes' and the
commands' model options) takes a shipped model's name as well as a path, and finds a path the checkout holds
(``models/supermag.onnx``) from any working folder (:func:`resolve_model_path`).

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
    "contact_eflesh": "contact_eflesh.onnx",  # the eFlesh board's, for its grip scene (the six rods)
    "contact_anyskin5": "contact_anyskin5.onnx",  # the AnySkin board's, for its grip scene (the six rods)
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


def resolve_model_path(name_or_path: str | Path) -> Path:
    """The model file a loader was given: a shipped model's name (``"supermag"``, ``"contact"``) is its file
    (:func:`shipped_model`); a path that exists is itself; a relative path that does not exist from the working
    folder but does from the source checkout's root (``models/supermag.onnx`` run from another folder) is the
    checkout's file; any other path is returned as given, for the loader to name as missing
    (:func:`missing_model_message`).
    """
    key = str(name_or_path)
    if key in SHIPPED_MODELS and not Path(key).exists():
        return models_dir() / SHIPPED_MODELS[key]  # absent outside a checkout: the loader names it missing
    path = Path(name_or_path)
    if path.exists() or path.is_absolute():
        return path
    in_checkout = _checkout() / path
    return in_checkout if in_checkout.is_file() else path


def missing_model_message(path: str | Path) -> str:
    """What a loader says of a model file that is not there: where it looked, and the shipped default."""
    path = Path(path)
    where = str(path) if path.is_absolute() else f"{path} (looked in {Path.cwd()} and {_checkout()})"
    default = models_dir() / SHIPPED_MODELS[DEFAULT_MODEL]
    shipped = (f"the shipped default is {default}, or the name '{DEFAULT_MODEL}'" if default.is_file() else
               "the shipped models come with a source checkout: clone the repository and `pip install -e .`")
    return f"model file not found: {where}; export one with `tactile-manip export`, or use a shipped model ({shipped})"
