"""A trained checkpoint run in torch eager mode behind the :class:`Reconstructor` interface (reference only).

The product runs exported models on onnxruntime (:mod:`tactile_manip.perception.reconstruct`); this module
exists so the speed-vs-error report can time the same weights in torch for reference, through the same
readings, estimator and trials as every other method. It runs exactly the graph that export writes
(:class:`~tactile_manip.learning.cvae.export.InferenceGraph`: axis selection, clamp, scaling, prior, decoder).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tactile_manip.learning.cvae.export import InferenceGraph, export_onnx, load_checkpoint
from tactile_manip.perception.reconstruct import Reconstructor


class TorchReconstructor(Reconstructor):
    """A training checkpoint (``RUN/best.pt``) as a reconstructor: prior-mean depth, no spread.

    Args:
        checkpoint: a checkpoint written by ``tactile-manip train``.
        threads: torch intra-op threads. torch has one process-wide setting, so this sets it for the
            whole process (as ``torch.set_num_threads`` does).
        pixel_mm: output pixel size, mm (the checkpoint does not store it; take it from the exported model).
        device: torch device to run on ("cpu", "cuda", "cuda:N"); readings go in and images come out as
            numpy on the host either way, so a GPU timing includes both copies.
    """

    def __init__(self, checkpoint: str | Path, *, threads: int = 1, pixel_mm: float = 0.1,
                 device: str = "cpu") -> None:
        if threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        torch.set_num_threads(int(threads))
        self.device = torch.device(device)
        if self.device.type == "cuda" and not torch.cuda.is_available():
            raise ValueError(f"device {device!r}: torch sees no CUDA GPU")
        model, spec, payload = load_checkpoint(checkpoint)
        self.graph = InferenceGraph(model, spec).eval().to(self.device)
        cfg = model.cfg
        self.input_shape = (cfg.taxel_rows, cfg.taxel_cols, 3)
        self.output_shape = (cfg.image_h, cfg.image_w)
        self.pixel_mm = float(pixel_mm)
        self.latent = cfg.latent
        self.model_config: dict[str, Any] = dict(payload["model_config"])
        self.name = f"supermag-{payload['train_config'].get('preset', 'model')}-torch"

    def _run(self, fields_ut: np.ndarray) -> tuple[np.ndarray, None]:
        eps = torch.zeros(len(fields_ut), 1, self.latent, device=self.device)
        with torch.inference_mode():
            depth, _ = self.graph(torch.from_numpy(np.ascontiguousarray(fields_ut)).to(self.device), eps)
        return depth.cpu().numpy().astype(np.float32, copy=False), None


def export_untrained(preset_name: str, folder: str | Path, *, seed: int = 0, pixel_mm: float = 0.1) -> Path:
    """Export a randomly initialised model of ``preset_name`` (a preset, or a training config ``.toml`` whose
    preset and ``[decoder]`` settings give the architecture) to ``folder/<name>.onnx`` (for timing only:
    latency does not depend on the weights). Returns the ONNX path; the checkpoint is written beside it."""
    from tactile_manip.config import to_dict
    from tactile_manip.learning.cvae.model import SuperMagCVAE
    from tactile_manip.learning.cvae.model import preset as make_preset
    from tactile_manip.learning.cvae.train import architecture, load_train_config

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(seed)
    if preset_name.endswith(".toml"):
        train_cfg = load_train_config(preset_name)
        name, mcfg = Path(preset_name).stem, architecture(train_cfg)
        preset_name, axes = train_cfg.preset, train_cfg.axes
    else:
        name, mcfg, axes = preset_name, make_preset(preset_name), "xyz"
    model = SuperMagCVAE(mcfg)
    ckpt = folder / f"{name}.pt"
    torch.save({"model": model.state_dict(), "model_config": to_dict(model.cfg),
                "input": {"clamp_ut": 500.0, "axes": axes},
                "train_config": {"preset": preset_name, "epochs": 0}, "data_fingerprint": "untrained"}, ckpt)
    out = folder / f"{name}.onnx"
    with warnings.catch_warnings():  # the legacy exporter's tracer notes say nothing about a timing model
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        export_onnx(ckpt, out, pixel_mm=pixel_mm, extra={"untrained": True})
    return out
