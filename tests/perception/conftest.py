"""Shared fixtures: tiny exported SuperMag models (untrained, seeded) for the reconstructor tests.

Export goes through the real path (training checkpoint -> ``export_onnx``, with its torch/onnxruntime parity
check), so these fixtures also catch a broken export. The models are small (40x40 and 24x32 images) and built
once per session.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from checks import TORCH_MISSING



@dataclass(frozen=True)
class ExportedModel:
    """An exported model file and what went into it."""

    path: Path
    taxels: tuple[int, int, int]
    image_hw: tuple[int, int]
    pixel_mm: float
    clamp_ut: float
    fingerprint: str
    metadata: dict[str, Any]


def _tiny_dataset(rows: int, cols: int, h: int, w: int, n: int = 6):
    from tactile_manip.data import PairedDataset, depth_image_spec

    rng = np.random.default_rng(0)
    field = rng.normal(0.0, 100.0, (n, rows, cols, 3)).astype(np.float32)
    return PairedDataset(
        readings=field, images=rng.integers(0, 50, (n, h, w), dtype=np.uint8),
        split=np.array(["train"] * (n - 2) + ["val", "test"]), image=depth_image_spec(),
        object_index=np.zeros(n, np.int16), object_names=np.array(["bar"]))


def _export(tmp: Path, *, rows: int, cols: int, h: int, w: int, pixel_mm: float) -> ExportedModel:
    # torch and onnx are the "train" extra: skip (only) model tests without them
    torch = pytest.importorskip("torch", reason=TORCH_MISSING)
    pytest.importorskip("onnx", reason="exporting a model needs onnx (pip install -e '.[train]')")
    pytest.importorskip("onnxruntime", reason="running a model needs onnxruntime (pip install -e '.[onnx]')")
    from tactile_manip.learning.cvae.data import InputSpec
    from tactile_manip.learning.cvae.export import export_onnx
    from tactile_manip.learning.cvae.model import SuperMagCVAE, preset
    from tactile_manip.learning.cvae.train import TrainConfig, _save_checkpoint

    torch.manual_seed(0)
    data = _tiny_dataset(rows, cols, h, w)
    mcfg = preset("small", taxel_rows=rows, taxel_cols=cols, axes=3, image_h=h, image_w=w)
    model = SuperMagCVAE(mcfg).eval()
    with torch.no_grad():
        # An untrained decoder outputs a small negative constant, which the final ReLU turns into an all-zero
        # image whatever the reading: the clamp and batch tests would then pass vacuously. Random (instead of
        # zero-initialised) modulation and a positive head bias give positive depths that depend on the input.
        for mod in model.decoder.mod:
            torch.nn.init.normal_(mod.proj.weight, std=1.0)
        model.decoder.head.bias[0] = 0.3
    cfg = TrainConfig(preset="small", epochs=1)
    spec = InputSpec(cfg.clamp_ut, cfg.axes)
    ckpt = tmp / "model.pt"
    _save_checkpoint(ckpt, model, torch.optim.AdamW(model.parameters()), mcfg, cfg, spec, data, {"epoch": 0})
    out = tmp / "model.onnx"
    with warnings.catch_warnings():
        # the legacy exporter's deprecation and tracer notes are export.py's business, not these tests'
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        meta = export_onnx(ckpt, out, pixel_mm=pixel_mm)
    return ExportedModel(out, (rows, cols, 3), (h, w), pixel_mm, spec.clamp_ut, data.fingerprint(), meta)


@pytest.fixture(scope="session")
def data_4x4():
    """Six random pairs in onnx_4x4's shapes (4x4x3 readings, 40x40 images)."""
    return _tiny_dataset(4, 4, 40, 40)


@pytest.fixture(scope="session")
def onnx_4x4(tmp_path_factory: pytest.TempPathFactory) -> ExportedModel:
    """A 4x4x3-taxel model with 40x40 images of 0.5 mm pixels."""
    return _export(tmp_path_factory.mktemp("onnx_4x4"), rows=4, cols=4, h=40, w=40, pixel_mm=0.5)


@pytest.fixture(scope="session")
def onnx_5x6(tmp_path_factory: pytest.TempPathFactory) -> ExportedModel:
    """A 5x6x3-taxel model with 24x32 images: another grid, non-square output."""
    return _export(tmp_path_factory.mktemp("onnx_5x6"), rows=5, cols=6, h=24, w=32, pixel_mm=0.25)


@pytest.fixture(params=["C kernel", "numpy"])
def pose_path(request):
    """Runs a test once with the pose stage's C kernel (skipped where it is not built) and once on the numpy
    path, which runs where the kernel is missing."""
    from tactile_manip.perception import pose_kernel

    if request.param == "C kernel" and not pose_kernel.available():
        pytest.skip(f"the C pose kernel is not available here ({pose_kernel.describe()})")
    if request.param == "numpy":
        with pose_kernel.numpy_path():
            yield request.param
    else:
        yield request.param
