"""Export a trained contact network to ONNX with everything inference needs inside the file.

The graph (the members' layers stacked into batched products, :class:`~.model.FusedContactModel`)
takes ``field_ut`` (B, T, R, C, A) float32, a window of T readings (frame 0 the newest; microtesla,
baseline-subtracted) and returns ``mean`` (B, K) and ``sigma`` (B, K) in the targets' units. Features and
standardisation run inside the graph. The JSON under the metadata key ``tactile_manip`` holds the kind
(``"contact"``), the target names and units, the input's shape, layout and units, the board layout, the
temporal context (frames, largest gap, the training stream's frame period), the normalisation, the training
and model configs, the data fingerprint and the validation RMSE, and where given the image centroid's share in a
combined position estimate (``image_position_weight``), the largest |field| of a reading the model answers for
(``input.plausible_field_ut``) and the targets' trained ranges (``targets.range``), which
:class:`~tactile_manip.perception.contact.ContactEstimator` reads with defaults where a file has none. Export
re-runs the file with onnxruntime on real and random windows and refuses to keep one that disagrees with torch.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tactile_manip.boards.identity import record_of_name
from tactile_manip.config import to_dict
from tactile_manip.data.targets import target_unit
from tactile_manip.learning.checkpoint import load_net_checkpoint
from tactile_manip.learning.contact.model import ContactModel, ContactModelConfig, FusedContactModel, count_parameters
from tactile_manip.learning.cvae.export import ExportError
from tactile_manip.outputs import unfinished
from tactile_manip.perception.reconstruct import METADATA_KEY
from tactile_manip.version import __version__

FORMAT_VERSION = 1
KIND = "contact"
PARITY_TOLERANCE = 1e-4   # relative to each target's training spread


def load_contact_checkpoint(path: str | Path) -> tuple[ContactModel, dict[str, Any]]:
    """The contact model (eval mode) and the checkpoint payload."""
    return load_net_checkpoint(path, KIND, "a contact model", lambda cfg: ContactModel(ContactModelConfig(**cfg)))


def export_contact_onnx(checkpoint: str | Path, out: str | Path, *, metrics: dict | None = None,
                        check_windows: np.ndarray | None = None,
                        image_position_weight: float | None = None, plausible_field_ut: float | None = None,
                        target_ranges: Mapping[str, tuple[float, float]] | None = None) -> dict[str, Any]:
    """Write ``out`` (.onnx) from ``checkpoint`` and return its metadata (with ``parity_max_abs``).

    ``check_windows`` (N, T, R, C, A): real input windows for the parity check (random ones are added).
    ``image_position_weight``: the image centroid's share in the position of a
    :class:`~tactile_manip.perception.tactile_estimator.TactileEstimator` built with this model (stored in the
    metadata; chosen with ``benchmarks/contact_position_fusion.py``); none: the model's own position.
    ``plausible_field_ut``: the largest |field| (uT) of a reading the model answers for (none: its board's bound,
    :data:`~tactile_manip.perception.estimator.PLAUSIBLE_FIELD_UT`). ``target_ranges``: the range [low, high] of
    each named target in the training data (none: the normalisation's mean +- 4 standard deviations).
    """
    if image_position_weight is not None and not 0.0 <= image_position_weight <= 1.0:
        raise ValueError(f"image_position_weight must be a share in [0, 1], got {image_position_weight!r}")
    if plausible_field_ut is not None and not (math.isfinite(plausible_field_ut) and plausible_field_ut > 0):
        raise ValueError(f"plausible_field_ut must be a finite number of uT > 0, got {plausible_field_ut!r}")
    ranges = {str(n): [float(lo), float(hi)] for n, (lo, hi) in (target_ranges or {}).items()}
    for name, (lo, hi) in ranges.items():
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"target_ranges[{name!r}] must be finite with low < high, got {[lo, hi]}")
    import onnx

    model, payload = load_contact_checkpoint(checkpoint)
    unknown = set(ranges) - set(payload["targets"])
    if unknown:
        raise ValueError(f"target_ranges names {sorted(unknown)}, which are not the model's targets "
                         f"({', '.join(payload['targets'])})")
    cfg = model.cfg
    example = torch.zeros(2, cfg.context_frames, *cfg.cells)
    final = Path(out)
    tmp = final.with_name(final.name + ".partial")
    final.parent.mkdir(parents=True, exist_ok=True)
    with unfinished(tmp):  # a failed export leaves no .partial behind
        fused = FusedContactModel(model).eval()  # one batched product per layer: fewer nodes, same function
        torch.onnx.export(fused, (example,), str(tmp), dynamo=False, opset_version=17, input_names=["field_ut"],
                          output_names=["mean", "sigma"],
                          dynamic_axes={"field_ut": {0: "batch"}, "mean": {0: "batch"}, "sigma": {0: "batch"}})
        meta = contact_metadata(model, payload, metrics or {})
        if image_position_weight is not None:
            meta["image_position_weight"] = float(image_position_weight)
        if plausible_field_ut is not None:
            meta["input"]["plausible_field_ut"] = float(plausible_field_ut)
        if ranges:
            meta["targets"]["range"] = ranges
        proto = onnx.load(str(tmp))
        entry = proto.metadata_props.add()
        entry.key, entry.value = METADATA_KEY, json.dumps(meta)
        proto.producer_name = "tactile_manip"
        onnx.save(proto, str(tmp))
        meta["parity_max_abs"] = check_contact_parity(model, tmp, check_windows)
        tmp.replace(final)
    return meta


def contact_metadata(model: ContactModel, payload: dict[str, Any], metrics: dict) -> dict[str, Any]:
    """The JSON stored in the file (see the module docstring)."""
    cfg = model.cfg
    names = list(payload["targets"])
    inp = payload["input"]
    return {
        "format_version": FORMAT_VERSION, "kind": KIND, "package_version": __version__,
        "input": {"name": "field_ut", "shape": ["batch", cfg.context_frames, *cfg.cells],
                  "units": "microtesla, baseline-subtracted (raw minus the no-contact field)",
                  "layout": "[frame, row, col, channel]; frame 0 the newest reading, frame k the reading k frames "
                            "before it", "channels": inp["channels"]},
        "board_layout": inp["layout"],
        **({"board": board} if (board := inp.get("board") or record_of_name(inp["layout"])) is not None else {}),
        "context": inp["context"],
        "targets": {"names": names, "units": [target_unit(n) for n in names]},
        "output": {"names": ["mean", "sigma"], "shape": ["batch", len(names)],
                   "what": "Gaussian mean and standard deviation per target, in the target's unit: the mixture of "
                           f"{cfg.members} ensemble members"},
        "normalisation": {"features": cfg.features,
                          "feature_offset": model.feature_offset.tolist(),
                          "feature_scale": model.feature_scale.tolist(),
                          "target_offset": model.target_offset.tolist(),
                          "target_scale": model.target_scale.tolist(),
                          "sigma_scale": model.sigma_scale.tolist(),
                          "what": "features standardised with the training split's mean and spread (inside the "
                                  "graph); outputs mapped back to target units; sigma times sigma_scale, fitted on "
                                  "the validation samples (68.3 % of their errors within one sigma)"},
        "sigma_calibration": payload.get("sigma_calibration", {}),
        "model_config": to_dict(cfg), "train_config": payload["train_config"],
        "training_data": payload.get("data", {}), "parameters": count_parameters(model), "metrics": metrics,
    }


def check_contact_parity(model: ContactModel, path: Path, windows: np.ndarray | None = None) -> float:
    """Max |ONNX - torch| over real and random windows, relative to the target spreads, or to the output itself
    where it is larger (the rounding of float32 grows with the value: an undertrained model's sigma on random
    windows may be hundreds of spreads); raises above tolerance (and removes ``path``)."""
    import onnxruntime as ort

    cfg = model.cfg
    rng = np.random.default_rng(0)
    batches = [rng.normal(0, 200, (8, cfg.context_frames, *cfg.cells)).astype(np.float32)]
    if windows is not None and len(windows):
        batches.append(np.asarray(windows[:64], dtype=np.float32))
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    scale = model.target_scale.numpy()
    worst = 0.0
    for w in batches:
        with torch.no_grad():
            ref = [t.numpy() for t in model(torch.from_numpy(w))]
        got = session.run(None, {"field_ut": w})
        got_one = [np.concatenate(o) for o in zip(*(session.run(None, {"field_ut": w[i:i + 1]}) for i in range(3)))]
        worst = max(worst, *(_relative_gap(a, b, scale) for a, b in zip(ref, got)),
                    *(_relative_gap(a[:3], b, scale) for a, b in zip(ref, got_one)))
    if not worst <= PARITY_TOLERANCE:
        path.unlink(missing_ok=True)
        raise ExportError(f"ONNX output differs from torch by {worst:.3g} target spreads (> {PARITY_TOLERANCE}); "
                          f"{path} was not kept")
    return worst


def _relative_gap(ref: np.ndarray, got: np.ndarray, scale: np.ndarray) -> float:
    """Largest |got - ref| in target spreads, or relative to ``ref`` itself where it is larger than the spread."""
    return float(np.max(np.abs(got - ref) / np.maximum(scale, np.abs(ref))))
