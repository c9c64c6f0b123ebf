"""The kinds of model the package trains and exports, in one table: what ``train`` and ``export`` run for each.

A training config names its kind (``kind = "contact"``; no ``kind``: the CVAE), and so does the checkpoint a run
writes. ``tactile-manip train`` looks the config's kind up here (:func:`kind_of_config`), ``export --checkpoint``
and ``export-model`` the checkpoint's (:func:`kind_of_checkpoint`), and each runs what the entry names. An entry
names its functions as ``"module:function"`` and they are imported only when a verb runs, so this module (and
``tactile-manip --help``) imports no torch. Adding a model: a folder beside ``cvae/`` and one entry in
:data:`KINDS`.
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from tactile_manip.errors import ConfigError

DEFAULT_KIND = "cvae"  # the kind of a config or checkpoint that names none


@dataclass(frozen=True)
class ModelKind:
    """One kind of model and the functions the verbs run for it.

    ``train`` and ``export`` are ``"module:function"`` names of functions that take the parsed command line
    (``tactile-manip train``'s; ``export --checkpoint``'s or ``export-model``'s) and return the exit status.
    """

    name: str         # the `kind` of a training config and of its checkpoints
    description: str  # one line: what the model reads and gives
    train: str        # "module:function": `tactile-manip train` on a config of this kind
    export: str       # "module:function": `export --checkpoint` / `export-model` on a checkpoint of this kind

    def __post_init__(self) -> None:
        for field in ("train", "export"):
            module, sep, function = getattr(self, field).partition(":")
            if not (module and sep and function):
                raise ValueError(f"ModelKind {self.name!r}: {field} must be 'module:function', got "
                                 f"{getattr(self, field)!r}")

    def run_train(self, args: argparse.Namespace) -> int:
        """Train on ``args.config`` (of this kind) as ``tactile-manip train`` does; the exit status."""
        return _resolve(self.train)(args)

    def run_export(self, args: argparse.Namespace) -> int:
        """Write ``args.checkpoint`` (of this kind) to ``args.out`` as ``export --checkpoint`` does; the exit
        status."""
        return _resolve(self.export)(args)


KINDS: dict[str, ModelKind] = {kind.name: kind for kind in (
    ModelKind("cvae", "SuperMag's conditional VAE: a depth image (mean and spread) from one reading",
              train="tactile_manip.learning.cvae.cli:run_train",
              export="tactile_manip.learning.cvae.cli:run_export"),
    ModelKind("angle_head", "the pose model's angle head: the contact's in-plane axis and its concentration from "
                            "one reading, attached to a pose model's ONNX file",
              train="tactile_manip.learning.angle_head.cli:run_train",
              export="tactile_manip.learning.angle_head.cli:run_export"),
    ModelKind("contact", "the contact network: contact targets (position, depth, force) with a sigma each from a "
                         "short window of readings",
              train="tactile_manip.learning.contact.cli:run_train",
              export="tactile_manip.learning.contact.cli:run_export"),
)}


def model_kind(name: str, *, source: str | Path | None = None) -> ModelKind:
    """The entry of :data:`KINDS` called ``name``.

    Raises:
        ConfigError: no kind is called ``name``; the message names ``source`` (the file that gave the name) and
            the known kinds.
    """
    try:
        return KINDS[name]
    except KeyError:
        where = f"{source}: " if source is not None else ""
        raise ConfigError(f"{where}unknown model kind {name!r}; the known kinds: {', '.join(KINDS)}") from None


def kind_of_config(path: str | Path) -> ModelKind:
    """The kind a training config names (:data:`DEFAULT_KIND` when it names none).

    A file that cannot be read or parsed counts as the default kind: its loader then names the fault.

    Raises:
        ConfigError: the config names an unknown kind.
    """
    import tomllib

    try:
        name = tomllib.loads(Path(path).read_text()).get("kind", DEFAULT_KIND)
    except (OSError, ValueError):
        return KINDS[DEFAULT_KIND]
    return model_kind(str(name), source=path)


def kind_of_checkpoint(path: str | Path) -> ModelKind:
    """The kind of the training checkpoint at ``path`` (:data:`DEFAULT_KIND` when it names none; imports torch).

    Raises:
        CheckpointError: the file is missing or not a training checkpoint.
        ConfigError: the checkpoint names an unknown kind.
    """
    from tactile_manip.learning.checkpoint import read_checkpoint

    return model_kind(str(read_checkpoint(path).get("kind", DEFAULT_KIND)), source=path)


def _resolve(target: str) -> Callable[[argparse.Namespace], int]:
    module, _, function = target.partition(":")
    return getattr(importlib.import_module(module), function)
