"""The kinds of model the package trains and exports, in one table: what ``train`` and ``export`` run for each.

A training config names its kind (``kind = "contact"``; no ``kind``: the CVAE), and so does the checkpoint a run
writes. ``tactile-manip train`` looks the config's kind up here (:func:`kind_of_config`), ``export --checkpoint``
and ``export-model`` the checkpoint's (:func:`kind_of_checkpoint`), and each runs what the entry names. An entry
names its functions as ``"module:function"`` and they are imported only when a verb runs, so this module (and
``tactile-manip --help``) imports no torch. Adding a model: a folder beside ``cvae/`` and one entry in
:data:`KINDS`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from tactile_manip.errors import ConfigError

DEFAULT_KIND = "cvae"  # the kind of a config or checkpoint that names none


@dataclass(frozen=True)
class TrainRequest:
    """What ``tactile-manip train`` asks of a kind: the config, the data, the run folder and the overrides.

    Attributes:
        config: the training TOML (its ``kind`` chose the entry).
        data: dataset files or shard folders, trained on as one.
        out: the run folder (checkpoints, history, plots).
        resume: continue ``out``'s own checkpoint.
        force: start over in an ``out`` that holds a run, replacing it.
        init: fine-tune from this checkpoint's weights (image models), or None.
        epochs, seed, threads: the config's values replaced where not None.
        device: the config's device replaced (image models), or None.
        max_minutes: the config's wall-time cap replaced, min (image models), or None.
        quiet: no progress display (the closing summary line is still printed).
        prior: contact models: simulated presses of the pad's twin that label its unlabelled presses
            (``unlabelled = "twin"``), or None.
    """

    config: str
    data: tuple[str, ...]
    out: str
    resume: bool = False
    force: bool = False
    init: str | None = None
    epochs: int | None = None
    seed: int | None = None
    threads: int | None = None
    device: str | None = None
    max_minutes: float | None = None
    quiet: bool = False
    prior: str | None = None


@dataclass(frozen=True)
class ExportRequest:
    """What ``export --checkpoint`` / ``export-model`` asks of a kind: the checkpoint, the ONNX file to write and
    the options that go with it (None: not given; each kind refuses the options that are not its own).

    Attributes:
        checkpoint: the training checkpoint (``RUN/best.pt``).
        out: the .onnx file to write.
        force: replace an earlier export at ``out`` (and ``card``).
        data: the training dataset(s): real readings for the parity check, pixel size and provenance.
        metrics: a ``results.json`` of ``tactile-manip evaluate`` to store inside.
        pixel_mm: image models: the output pixel size, mm.
        card, history, table, latency: image models: the model card to write and what goes into it.
        attach_to: angle heads: the pose model (.onnx) to copy to ``out`` with the head inside.
        head_symmetries: angle heads: symmetric copies read per reading (1 or 8).
        image_symmetry: image models and angle heads: the decoder's symmetric average ("none", "rotations",
            "all"), or None for the default.
        image_position_weight: contact models: the reconstructed image's share in the fused position.
    """

    checkpoint: str
    out: str
    force: bool = False
    data: tuple[str, ...] = ()
    metrics: str | None = None
    pixel_mm: float | None = None
    card: str | None = None
    history: str | None = None
    table: str | None = None
    latency: str | None = None
    attach_to: str | None = None
    head_symmetries: int = 8
    image_symmetry: str | None = None
    image_position_weight: float | None = None


@dataclass(frozen=True)
class ModelKind:
    """One kind of model and the functions the verbs run for it.

    ``train`` and ``export`` are ``"module:function"`` names of functions that take a :class:`TrainRequest` or an
    :class:`ExportRequest` and return the exit status.
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

    def run_train(self, request: TrainRequest) -> int:
        """Train on ``request.config`` (of this kind) as ``tactile-manip train`` does; the exit status."""
        return _resolve(self.train)(request)

    def run_export(self, request: ExportRequest) -> int:
        """Write ``request.checkpoint`` (of this kind) to ``request.out`` as ``export --checkpoint`` does; the exit
        status."""
        return _resolve(self.export)(request)


KINDS: dict[str, ModelKind] = {kind.name: kind for kind in (
    ModelKind("cvae", "SuperMag's conditional VAE: a depth image (mean and spread) from one reading",
              train="tactile_manip.learning.cvae.verbs:run_train",
              export="tactile_manip.learning.cvae.verbs:run_export"),
    ModelKind("angle_head", "the pose model's angle head: the contact's in-plane axis and its concentration from "
                            "one reading, attached to a pose model's ONNX file",
              train="tactile_manip.learning.angle_head.verbs:run_train",
              export="tactile_manip.learning.angle_head.verbs:run_export"),
    ModelKind("contact", "the contact network: contact targets (position, depth, force) with a sigma each from a "
                         "short window of readings",
              train="tactile_manip.learning.contact.verbs:run_train",
              export="tactile_manip.learning.contact.verbs:run_export"),
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


def _resolve(target: str) -> Callable[[TrainRequest | ExportRequest], int]:
    module, _, function = target.partition(":")
    return getattr(importlib.import_module(module), function)
