"""Reading a training checkpoint (``RUN/best.pt``, ``RUN/checkpoint.pt``) back, with one clear error per fault.

A checkpoint is a ``torch.save`` dict written by ``tactile_manip.learning.cvae.train``; it is loaded with
``weights_only=True`` (files are data). A truncated file, a foreign one (any other ``torch.save`` dict, a zip,
a pickle) or one of another architecture raises :class:`CheckpointError` naming the file and what is wrong.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from tactile_manip.errors import TactileManipError

REQUIRED_KEYS = ("model", "model_config", "input")


class CheckpointError(TactileManipError, ValueError):
    """A file is missing, unreadable, or not a tactile_manip training checkpoint."""


def read_checkpoint(path: str | Path) -> dict[str, Any]:
    """The payload of the training checkpoint at ``path`` (a dict with at least REQUIRED_KEYS).

    Raises:
        CheckpointError: missing, a directory, truncated or not a torch file, or a dict without our keys.
    """
    path = Path(path)
    if path.is_dir():
        raise CheckpointError(f"{path} is a directory; give a checkpoint file (RUN/best.pt)")
    if not path.is_file():
        raise CheckpointError(f"checkpoint not found: {path} (train one with `tactile-manip train`)")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - torch raises RuntimeError, UnpicklingError, EOFError, ... by format
        reason = " ".join(str(e).split())[:160]
        raise CheckpointError(f"{path} is not a readable torch checkpoint (truncated or another format): "
                              f"{type(e).__name__}: {reason}") from e
    missing = [k for k in REQUIRED_KEYS if not isinstance(payload, dict) or k not in payload]
    if missing:
        raise CheckpointError(f"{path} is not a tactile_manip training checkpoint (no {', '.join(missing)}; "
                              "expected RUN/best.pt or RUN/checkpoint.pt of `tactile-manip train`)")
    return payload


def load_net_checkpoint(path: str | Path, kind: str, what: str, build: Any) -> tuple[Any, dict[str, Any]]:
    """A small network's checkpoint of ``kind`` (e.g. "contact", "angle_head"; ``what`` names it in errors):
    ``build(model_config)`` makes the module from the stored config (lists as tuples), whose weights are then
    loaded; returns it in eval mode with the payload. Raises :class:`CheckpointError` for another kind or
    weights that do not fit."""
    payload = read_checkpoint(path)
    if payload.get("kind") != kind:
        raise CheckpointError(f"{path} is not {what} checkpoint (kind {payload.get('kind', 'cvae')!r})")
    try:
        model = build({k: tuple(v) if isinstance(v, list) else v for k, v in payload["model_config"].items()})
        model.load_state_dict(payload["model"])
    except (TypeError, ValueError, RuntimeError) as e:
        raise CheckpointError(f"{path}: the checkpoint does not fit this code's {what.split(' ', 1)[1]} "
                              f"({type(e).__name__}: {' '.join(str(e).split())[:160]})") from e
    return model.eval(), payload
