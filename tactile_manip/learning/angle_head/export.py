"""Attach a trained angle head to an exported pose model: one file with the image graphs and the head.

``tactile-manip export --checkpoint RUN/best.pt --attach-to models/base.onnx --out models/new.onnx`` exports
the head (:mod:`.model`) to ONNX, ``field_ut`` (N, R, C, A) -> ``axis`` (N, 2), checks it on
onnxruntime against torch, and writes a copy of the base model with the head (base64) and its record (JSON:
training config, data, validation figures) in the metadata (:mod:`tactile_manip.perception.angle_head`). By
default the graph reads each reading in the board's 8 symmetric copies and averages their axes
(:func:`symmetrized`; ``--head-symmetries 1`` leaves that out). The base model's graphs and metadata are kept
as they are; its input shape must be the head's.
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tactile_manip.learning.angle_head.model import AngleHead, AngleModelConfig, SymmetrizedAngleHead, count_parameters
from tactile_manip.learning.checkpoint import load_net_checkpoint
from tactile_manip.learning.cvae.export import ExportError
from tactile_manip.outputs import unfinished
from tactile_manip.perception.angle_head import ANGLE_HEAD_KEY, ANGLE_HEAD_META_KEY
from tactile_manip.perception.one_reading import encode
from tactile_manip.perception.board_symmetry import IMAGE_SYMMETRIES
from tactile_manip.perception.reconstruct import METADATA_KEY, read_metadata
from tactile_manip.perception.symmetry import transform_reading
from tactile_manip.version import __version__

KIND = "angle_head"
PARITY_TOLERANCE = 1e-3   # largest |ONNX - torch| of the axis vector, relative to its length (at least 1)


def load_angle_checkpoint(path: str | Path) -> tuple[AngleHead, dict[str, Any]]:
    """The angle head (eval mode) and the checkpoint payload."""
    return load_net_checkpoint(path, KIND, "an angle head", lambda cfg: AngleHead(AngleModelConfig(**cfg)))


def symmetrized(model: AngleHead) -> SymmetrizedAngleHead:
    """``model`` read over the board's 8 symmetries (4 quarter turns, with and without the mirror): the maps
    of :func:`~tactile_manip.perception.symmetry.transform_reading` on the flattened reading, and the same
    symmetry's action on the axis (a mirror negates it, a quarter turn adds 90 deg), inverted."""
    cells = tuple(model.cfg.cells)
    n = int(np.prod(cells))
    basis = np.eye(n, dtype=np.float64).reshape(n, *cells)
    reading_maps, axis_maps = [], []
    for mirror in (False, True):
        for turns in range(4):
            reading_maps.append(transform_reading(basis, turns, mirror).reshape(n, n).T)
            # a copy's doubled angle is (+-2t + turns * pi): back by (-1)^turns, then the mirror's sign on sin
            axis_maps.append(np.diag([1.0, -1.0 if mirror else 1.0]) * (-1.0) ** turns)
    return SymmetrizedAngleHead(model, torch.from_numpy(np.stack(reading_maps)),
                                torch.from_numpy(np.stack(axis_maps))).eval()


def head_onnx_bytes(model: AngleHead | SymmetrizedAngleHead) -> bytes:
    """The head as a serialised ONNX graph with a dynamic batch dimension."""
    buffer = io.BytesIO()
    example = torch.zeros(2, *model.cfg.cells)
    torch.onnx.export(model, (example,), buffer, dynamo=False, opset_version=17, input_names=["field_ut"],
                      output_names=["axis"], dynamic_axes={"field_ut": {0: "batch"}, "axis": {0: "batch"}})
    return buffer.getvalue()


def attach_angle_head(checkpoint: str | Path, base: str | Path, out: str | Path, *,
                      check_readings: np.ndarray | None = None, symmetries: bool = True,
                      image_symmetry: str | None = None) -> dict[str, Any]:
    """Write ``out``: ``base`` with the head of ``checkpoint`` attached; returns the head's record (with
    ``parity_max_abs``). ``check_readings`` (N, R, C, A): real readings for the parity check. ``symmetries``:
    the graph reads every reading in its 8 symmetric copies and averages their axes (:func:`symmetrized`).
    ``image_symmetry``: what the copy averages its images over
    (:data:`~tactile_manip.perception.board_symmetry.IMAGE_SYMMETRIES`; None: as ``base`` says)."""
    import onnx

    if image_symmetry is not None and image_symmetry not in IMAGE_SYMMETRIES:
        raise ValueError(f"image_symmetry must be one of {', '.join(IMAGE_SYMMETRIES)}, got {image_symmetry!r}")

    head, payload = load_angle_checkpoint(checkpoint)
    model = symmetrized(head) if symmetries else head
    base_meta = read_metadata(base)  # a readable pose model, or a one-line ModelFileError
    base_cells = tuple(int(v) for v in base_meta["input"]["shape"][1:])
    if base_cells != tuple(model.cfg.cells):
        raise ExportError(f"{base} reads readings of shape {base_cells}, the angle head {tuple(model.cfg.cells)}: "
                          "they are not for the same board")
    graph = head_onnx_bytes(model)
    parity = check_head_parity(model, graph, check_readings)
    record = {"format_version": 1, "kind": KIND, "package_version": __version__,
              "input": {"name": "field_ut", "shape": ["batch", *model.cfg.cells],
                        "units": "microtesla, baseline-subtracted"},
              "output": {"name": "axis", "shape": ["batch", 2],
                         "what": "kappa (cos 2t, sin 2t): von Mises natural parameter of the doubled axis angle"},
              "parameters": count_parameters(head), "symmetries": 8 if symmetries else 1,
              "model_config": payload["model_config"],
              "train_config": payload["train_config"], "training_data": payload.get("data", {}),
              "validation": payload.get("val", {}), "parity_max_abs": parity}
    proto = onnx.load(str(base))
    keep = [(p.key, p.value) for p in proto.metadata_props if p.key not in (ANGLE_HEAD_KEY, ANGLE_HEAD_META_KEY)]
    if image_symmetry is not None:  # the pose model's own record says what its images are averaged over
        keep = [(key, json.dumps({**json.loads(value), "image_symmetry": image_symmetry}) if key == METADATA_KEY
                 else value) for key, value in keep]
    del proto.metadata_props[:]
    for key, value in [*keep, (ANGLE_HEAD_KEY, encode(graph)), (ANGLE_HEAD_META_KEY, json.dumps(record))]:
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    final = Path(out)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.with_name(final.name + ".partial")
    with unfinished(tmp):
        onnx.save(proto, str(tmp))
        tmp.replace(final)
    return record


def check_head_parity(model: AngleHead | SymmetrizedAngleHead, graph: bytes,
                      readings: np.ndarray | None = None) -> float:
    """Max |ONNX - torch| of the axis vector over real and random readings, relative to its length (at least
    1); raises above :data:`PARITY_TOLERANCE`."""
    import onnxruntime as ort

    rng = np.random.default_rng(0)
    batches = [rng.normal(0, 100, (8, *model.cfg.cells)).astype(np.float32),
               np.zeros((1, *model.cfg.cells), np.float32)]
    if readings is not None and len(readings):
        batches.append(np.asarray(readings[:64], dtype=np.float32))
    session = ort.InferenceSession(graph, providers=["CPUExecutionProvider"])
    worst = 0.0
    for x in batches:
        with torch.no_grad():
            ref = model(torch.from_numpy(x)).numpy()
        got = session.run(None, {"field_ut": x})[0]
        scale = np.maximum(1.0, np.linalg.norm(ref, axis=1, keepdims=True))
        worst = max(worst, float(np.max(np.abs(got - ref) / scale)))
    if not worst <= PARITY_TOLERANCE:
        raise ExportError(f"the angle head's ONNX output differs from torch by {worst:.3g} (> {PARITY_TOLERANCE}); "
                          "nothing was written")
    return worst
