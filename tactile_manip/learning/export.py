"""Export a trained CVAE to ONNX (prior + decoder only) with everything inference needs inside the file.

The graph takes ``field_ut`` (B, R, C, 3) float32 microtesla, baseline-subtracted, and ``eps`` (B, K, Z)
standard-normal samples, and returns ``depth_mm`` (B, H, W), the mean of the K decoded means, and
``spread_mm`` (B, H, W), their standard deviation. Axis selection, the +-clamp and the scaling to [-1, 1]
happen inside the graph, so the runtime cannot apply them differently from training. ``eps = 0`` with
K = 1 gives the deterministic prior-mean reconstruction.

The JSON under the metadata key ``tactile_manip`` holds: format version, input layout, units, axes, clamp and
scaling, output size and pixel size, preset and architecture, training config, data fingerprint, metrics,
package version. Export re-runs the ONNX model with onnxruntime on real and random inputs and refuses to
write a file that disagrees with torch.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from tactile_manip.errors import TactileManipError
from tactile_manip.learning.checkpoint import CheckpointError, read_checkpoint
from tactile_manip.learning.data import AXIS_SETS, InputSpec
from tactile_manip.learning.model import CVAEConfig, SuperMagCVAE, count_parameters
from tactile_manip.version import __version__

METADATA_KEY = "tactile_manip"
FORMAT_VERSION = 1
PARITY_TOLERANCE_MM = 1e-4


class ExportError(TactileManipError, RuntimeError):
    """The exported model does not reproduce torch, or the checkpoint cannot be exported."""


class InferenceGraph(nn.Module):
    """What runs at inference: input scaling, prior, K decoder samples, mean and spread."""

    def __init__(self, model: SuperMagCVAE, spec: InputSpec) -> None:
        super().__init__()
        self.model = model
        self.axes = list(AXIS_SETS[spec.axes])
        self.clamp_ut = float(spec.clamp_ut)

    def forward(self, field_ut: torch.Tensor, eps: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x = field_ut[..., self.axes].clamp(-self.clamp_ut, self.clamp_ut) / self.clamp_ut
        return self.model.generate(x.flatten(1), eps)


def load_checkpoint(path: str | Path) -> tuple[SuperMagCVAE, InputSpec, dict[str, Any]]:
    """Model (eval mode), input spec and the raw checkpoint payload from a training checkpoint."""
    payload = read_checkpoint(path)
    try:
        mcfg = CVAEConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in payload["model_config"].items()})
        model = SuperMagCVAE(mcfg)
        model.load_state_dict(payload["model"])
        spec = InputSpec(**payload["input"])
    except (TypeError, ValueError, RuntimeError, AttributeError) as e:  # another code version or architecture
        raise CheckpointError(f"{path}: the checkpoint does not fit this code's model "
                              f"({type(e).__name__}: {' '.join(str(e).split())[:160]})") from e
    return model.eval(), spec, payload


def export_onnx(checkpoint: str | Path, out: str | Path, *, pixel_mm: float, metrics: dict | None = None,
                extra: dict | None = None, check_readings: np.ndarray | None = None) -> dict[str, Any]:
    """Write ``out`` (.onnx) from ``checkpoint`` and return its metadata.

    ``check_readings`` (N, R, C, 3) real readings for the parity check (random ones are added).
    """
    import onnx

    model, spec, payload = load_checkpoint(checkpoint)
    cfg = model.cfg
    graph = InferenceGraph(model, spec).eval()
    field = torch.zeros(2, cfg.taxel_rows, cfg.taxel_cols, 3)
    eps = torch.zeros(2, 3, cfg.latent)
    out = Path(out)
    final, out = out, out.with_name(out.name + ".partial")  # an existing model is replaced only by a checked one
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.onnx.export(graph, (field, eps), str(out), dynamo=False, opset_version=17,
                      input_names=["field_ut", "eps"], output_names=["depth_mm", "spread_mm"],
                      dynamic_axes={"field_ut": {0: "batch"}, "eps": {0: "batch", 1: "samples"},
                                    "depth_mm": {0: "batch"}, "spread_mm": {0: "batch"}})
    meta = _metadata(model, spec, payload, pixel_mm, metrics or {}, extra or {})
    proto = onnx.load(str(out))
    entry = proto.metadata_props.add()
    entry.key, entry.value = METADATA_KEY, json.dumps(meta)
    proto.producer_name = "tactile_manip"
    onnx.save(proto, str(out))
    meta["parity_max_abs_mm"] = check_parity(graph, out, check_readings)
    out.replace(final)
    return meta


def _metadata(model: SuperMagCVAE, spec: InputSpec, payload: dict, pixel_mm: float, metrics: dict,
              extra: dict) -> dict[str, Any]:
    cfg = model.cfg
    return {
        "format_version": FORMAT_VERSION,
        "package_version": __version__,
        "input": {"name": "field_ut", "shape": ["batch", cfg.taxel_rows, cfg.taxel_cols, 3],
                  "layout": "[row, col, axis], row 0 at +y, column 0 at -x, axes (x, y, z) of the pad frame",
                  "units": "microtesla, baseline-subtracted", "axes_used": spec.axes, "clamp_ut": spec.clamp_ut,
                  "scaling": "clamp to +-clamp_ut, divide by clamp_ut"},
        "noise": {"name": "eps", "shape": ["batch", "samples", cfg.latent], "distribution": "standard normal; "
                  "zeros with samples = 1 give the prior-mean reconstruction"},
        "output": {"names": ["depth_mm", "spread_mm"], "shape": ["batch", cfg.image_h, cfg.image_w],
                   "units": "mm of indentation, >= 0", "pixel_mm": pixel_mm,
                   "layout": "pixel (0, 0) at the (-x, +y) corner of the pad"},
        "preset": payload["train_config"]["preset"], "model_config": payload["model_config"],
        "train_config": payload["train_config"], "data_fingerprint": payload["data_fingerprint"],
        "parameters": count_parameters(model, inference_only=True), "metrics": metrics, **extra,
    }


def check_parity(graph: InferenceGraph, path: Path, readings: np.ndarray | None = None) -> float:
    """Max |ONNX - torch| (mm) over real and random readings, K = 1 and K = 4; raises above tolerance."""
    import onnxruntime as ort

    cfg = graph.model.cfg
    rng = np.random.default_rng(0)
    fields = [rng.normal(0, 150, (4, cfg.taxel_rows, cfg.taxel_cols, 3)).astype(np.float32)]
    if readings is not None and len(readings):
        fields.append(np.asarray(readings[:16], dtype=np.float32))
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    worst = 0.0
    for f in fields:
        for k in (1, 4):
            eps = rng.standard_normal((len(f), k, cfg.latent)).astype(np.float32)
            with torch.no_grad():
                ref = [t.numpy() for t in graph(torch.from_numpy(f), torch.from_numpy(eps))]
            got = session.run(None, {"field_ut": f, "eps": eps})
            worst = max(worst, *(float(np.abs(a - b).max()) for a, b in zip(ref, got)))
    if not worst <= PARITY_TOLERANCE_MM:
        path.unlink(missing_ok=True)
        raise ExportError(f"ONNX output differs from torch by {worst:.3g} mm (> {PARITY_TOLERANCE_MM} mm); "
                          f"{path} was not kept")
    return worst
