"""Export a trained CVAE to ONNX (prior + decoder only) with everything inference needs inside the file.

The graph takes ``field_ut`` (B, R, C, A) float32 readings (microtesla, baseline-subtracted, for the magnetic
sensors; whatever unit the training data had otherwise) and ``eps`` (B, K, Z) standard-normal samples, and
returns ``depth_mm`` (B, H, W), the mean of the K decoded means, and ``spread_mm`` (B, H, W), their standard
deviation (in the training images' unit: mm of indentation for depth images). Channel selection, the
normalisation, the clamp, the scaling to [-1, 1] and the map back to the image unit happen inside the graph,
so the runtime cannot apply them differently from training. ``eps = 0`` with
K = 1 gives the deterministic prior-mean reconstruction.

Beside it, the file carries the prior-mean reconstruction of exactly one reading (``field_ut`` (1, R, C, A) ->
``depth_mm`` (1, H, W), static shapes, no mean/spread tail), base64 under the metadata key
:data:`~tactile_manip.perception.one_reading.ONE_READING_KEY`: what a control loop runs
(:mod:`tactile_manip.perception.one_reading`).

The JSON under the metadata key ``tactile_manip`` holds: format version, input layout, units, axes, clamp and
scaling, output size and pixel size, preset and architecture, training config, data fingerprint, metrics,
package version. Export re-runs the ONNX model with onnxruntime on real and random inputs and refuses to
write a file that disagrees with torch.
"""

from __future__ import annotations

import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from tactile_manip.errors import TactileManipError
from tactile_manip.learning.checkpoint import CheckpointError, read_checkpoint
from tactile_manip.learning.cvae.data import InputSpec, OutputSpec
from tactile_manip.learning.cvae.model import CVAEConfig, SuperMagCVAE, count_parameters
from tactile_manip.perception.one_reading import ONE_READING_KEY, encode, open_one_reading
from tactile_manip.outputs import unfinished
from tactile_manip.perception.board_symmetry import IMAGE_SYMMETRIES
from tactile_manip.perception.reconstruct import METADATA_KEY
from tactile_manip.version import __version__

FORMAT_VERSION = 1
PARITY_TOLERANCE_MM = 1e-4


class ExportError(TactileManipError, RuntimeError):
    """The exported model does not reproduce torch, or the checkpoint cannot be exported."""


class InferenceGraph(nn.Module):
    """What runs at inference: input scaling, prior, K decoder samples, mean and spread."""

    def __init__(self, model: SuperMagCVAE, spec: InputSpec, output: OutputSpec | None = None) -> None:
        super().__init__()
        self.model = model
        self.spec = spec
        self.output = output or OutputSpec()

    def forward(self, field_ut: torch.Tensor, eps: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mean, spread = self.model.generate(self.spec.scale(field_ut), eps)
        if self.output != OutputSpec():  # the identity adds no nodes to depth models
            mean, spread = self.output.offset + self.output.scale * mean, self.output.scale * spread
        return mean, spread


class OneReadingGraph(InferenceGraph):
    """The prior-mean reconstruction of one reading: ``field_ut`` (1, R, C, A) -> ``depth_mm`` (1, H, W), what
    :class:`InferenceGraph` gives with ``eps`` = 0 and K = 1, without the sample dimension and the tail."""

    def forward(self, field_ut: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        mean, _ = self.model.prior_mean_decode(self.spec.scale(field_ut), with_logvar=False)
        return mean if self.output == OutputSpec() else self.output.offset + self.output.scale * mean


def load_checkpoint(path: str | Path) -> tuple[SuperMagCVAE, InputSpec, dict[str, Any]]:
    """Model (eval mode), input spec and the raw checkpoint payload (its "output" key: the OutputSpec)."""
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
                extra: dict | None = None, check_readings: np.ndarray | None = None,
                plausible_field_ut: float | None = None, image_symmetry: str = "none") -> dict[str, Any]:
    """Write ``out`` (.onnx) from ``checkpoint`` and return its metadata.

    ``image_symmetry``: what the loaded model averages each image over
    (:data:`~tactile_manip.perception.board_symmetry.IMAGE_SYMMETRIES`; stored in the metadata, applied by
    :class:`~tactile_manip.perception.reconstruct.OnnxReconstructor`).

    ``check_readings`` (N, R, C, 3) real readings for the parity check (random ones are added).
    ``plausible_field_ut``: the largest |field| (uT) of a reading the model answers for, stored as
    ``input.plausible_field_ut`` (none: the pose estimator takes its board's bound,
    :data:`~tactile_manip.perception.estimator.PLAUSIBLE_FIELD_UT`).
    """
    if image_symmetry not in IMAGE_SYMMETRIES:
        raise ValueError(f"image_symmetry must be one of {', '.join(IMAGE_SYMMETRIES)}, got {image_symmetry!r}")
    if plausible_field_ut is not None and not (math.isfinite(plausible_field_ut) and plausible_field_ut > 0):
        raise ValueError(f"plausible_field_ut must be a finite number of uT > 0, got {plausible_field_ut!r}")
    import onnx

    model, spec, payload = load_checkpoint(checkpoint)
    cfg = model.cfg
    graph = InferenceGraph(model, spec, OutputSpec(**payload.get("output", {}))).eval()
    field = torch.zeros(2, cfg.taxel_rows, cfg.taxel_cols, spec.channels)
    eps = torch.zeros(2, 3, cfg.latent)
    out = Path(out)
    final, out = out, out.with_name(out.name + ".partial")  # an existing model is replaced only by a checked one
    out.parent.mkdir(parents=True, exist_ok=True)
    with unfinished(out):  # a failed export leaves no .partial behind
        torch.onnx.export(graph, (field, eps), str(out), dynamo=False, opset_version=17,
                          input_names=["field_ut", "eps"], output_names=["depth_mm", "spread_mm"],
                          dynamic_axes={"field_ut": {0: "batch"}, "eps": {0: "batch", 1: "samples"},
                                        "depth_mm": {0: "batch"}, "spread_mm": {0: "batch"}})
        one = OneReadingGraph(model, spec, graph.output).eval()
        one_bytes = io.BytesIO()
        torch.onnx.export(one, (field[:1],), one_bytes, dynamo=False, opset_version=17, input_names=["field_ut"],
                          output_names=["depth_mm"])
        meta = _metadata(model, spec, payload, pixel_mm, metrics or {}, extra or {})
        if plausible_field_ut is not None:
            meta["input"]["plausible_field_ut"] = float(plausible_field_ut)
        meta["image_symmetry"] = image_symmetry
        proto = onnx.load(str(out))
        for key, value in ((METADATA_KEY, json.dumps(meta)), (ONE_READING_KEY, encode(one_bytes.getvalue()))):
            entry = proto.metadata_props.add()
            entry.key, entry.value = key, value
        proto.producer_name = "tactile_manip"
        onnx.save(proto, str(out))
        meta["parity_max_abs_mm"] = check_parity(graph, out, check_readings)
        out.replace(final)
    return meta


def _metadata(model: SuperMagCVAE, spec: InputSpec, payload: dict, pixel_mm: float, metrics: dict,
              extra: dict) -> dict[str, Any]:
    cfg = model.cfg
    data = payload.get("data", {})
    channels = data.get("channels", {"names": ["x", "y", "z"], "kind": "magnetic_vector", "unit": "uT"})
    image = data.get("image", {"unit": "mm"})
    magnetic = channels["kind"] == "magnetic_vector" and channels["unit"] == "uT"
    scaling = ("clamp to +-clamp_ut, divide by clamp_ut" if not spec.offset else
               "subtract offset, divide by spread (per channel, training split), clamp to +-clamp_std, divide by "
               "clamp_std")
    return {
        "format_version": FORMAT_VERSION,
        "package_version": __version__,
        "input": {"name": "field_ut", "shape": ["batch", cfg.taxel_rows, cfg.taxel_cols, spec.channels],
                  "layout": f"[row, col, channel], row 0 at +y, column 0 at -x, channels {channels['names']}",
                  "units": "microtesla, baseline-subtracted" if magnetic else channels["unit"],
                  "channels": channels, "axes_used": spec.axes, "clamp_ut": spec.clamp_ut,
                  "offset": list(spec.offset), "spread": list(spec.spread), "clamp_std": spec.clamp_std,
                  "scaling": scaling},
        "noise": {"name": "eps", "shape": ["batch", "samples", cfg.latent], "distribution": "standard normal; "
                  "zeros with samples = 1 give the prior-mean reconstruction"},
        "one_reading": {"metadata_key": ONE_READING_KEY, "encoding": "base64 ONNX",
                        "input": {"name": "field_ut", "shape": [1, cfg.taxel_rows, cfg.taxel_cols, spec.channels]},
                        "output": {"name": "depth_mm", "shape": [1, cfg.image_h, cfg.image_w]},
                        "what": "the prior-mean reconstruction of one reading (eps = 0, samples = 1): the same "
                                "image as the main graph, with static shapes and without the mean/spread tail"},
        "output": {"names": ["depth_mm", "spread_mm"], "shape": ["batch", cfg.image_h, cfg.image_w],
                   "units": "mm of indentation, >= 0" if image["unit"] == "mm" else image["unit"],
                   "image": image, "pixel_mm": pixel_mm,
                   "layout": "pixel (0, 0) at the (-x, +y) corner of the pad"},
        # the board whose readings the model takes (tactile_manip.boards); 4x4 data is the SuperMag board's
        "board_layout": ("supermag-4x4" if (cfg.taxel_rows, cfg.taxel_cols) == (4, 4)
                         else f"grid-{cfg.taxel_rows}x{cfg.taxel_cols}"),
        "preset": payload["train_config"]["preset"], "model_config": payload["model_config"],
        "train_config": payload["train_config"], "data_fingerprint": payload["data_fingerprint"],
        "training": _training_record(payload.get("state", {})),
        "parameters": count_parameters(model, inference_only=True), "metrics": metrics, **extra,
    }


def _training_record(state: dict) -> dict[str, Any]:
    """How far the checkpoint was trained (``epochs_run`` 0: untrained weights; galleries leave it out)."""
    best = state.get("best_psnr")
    return {"epochs_run": int(state.get("epoch", 0)), "best_epoch": int(state.get("best_epoch", 0)),
            "best_val_psnr_db": float(best) if best is not None and math.isfinite(best) else None}


def check_parity(graph: InferenceGraph, path: Path, readings: np.ndarray | None = None) -> float:
    """Max |ONNX - torch| (mm) over real and random readings, K = 1 and K = 4, and of the one-reading graph on
    each reading alone; raises above tolerance (and removes ``path``)."""
    import onnxruntime as ort

    cfg = graph.model.cfg
    rng = np.random.default_rng(0)
    spec = graph.spec
    centre, width = (np.asarray(spec.offset), np.asarray(spec.spread)) if spec.offset else (0.0, 150.0)
    fields = [(centre + width * rng.normal(0, 1, (4, cfg.taxel_rows, cfg.taxel_cols, spec.channels))).astype(np.float32)]
    if readings is not None and len(readings):
        fields.append(np.asarray(readings[:16], dtype=np.float32))
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    try:
        one = open_one_reading(ort, session, where=str(path), options=ort.SessionOptions(),
                               providers=["CPUExecutionProvider"],
                               input_shape=(cfg.taxel_rows, cfg.taxel_cols, spec.channels),
                               output_shape=(cfg.image_h, cfg.image_w), latent=cfg.latent, probe_centre=centre,
                               probe_width=width, error=ExportError)
    except ExportError:
        path.unlink(missing_ok=True)
        raise
    worst = 0.0
    for f in fields:
        for k in (1, 4):
            eps = rng.standard_normal((len(f), k, cfg.latent)).astype(np.float32)
            with torch.no_grad():
                ref = [t.numpy() for t in graph(torch.from_numpy(f), torch.from_numpy(eps))]
            got = session.run(None, {"field_ut": f, "eps": eps})
            worst = max(worst, *(float(np.abs(a - b).max()) for a, b in zip(ref, got)))
        with torch.no_grad():
            ref = graph(torch.from_numpy(f), torch.zeros(len(f), 1, cfg.latent))[0].numpy()
        got = np.concatenate([one.run(None, {"field_ut": reading[None]})[0] for reading in f])
        worst = max(worst, float(np.abs(ref - got).max()))
    tolerance = PARITY_TOLERANCE_MM * graph.output.scale  # 1e-4 of the image range for images not in mm
    if not worst <= tolerance:
        path.unlink(missing_ok=True)
        raise ExportError(f"ONNX output differs from torch by {worst:.3g} (> {tolerance:.3g}, image units); "
                          f"{path} was not kept")
    return worst
