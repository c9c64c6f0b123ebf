"""Shared fixtures of the speed-vs-error report tests: a handful of unseen-object readings, a tiny model."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
from checks import TORCH_MISSING

ROOT = Path(__file__).resolve().parents[2]
DATASET_CONFIG = ROOT / "configs" / "dataset" / "supermag.toml"


@pytest.fixture(scope="session")
def bench_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One simulated press of each unseen test object of the SuperMag config (7 readings), as a dataset file."""
    from tactile_manip.bench.accuracy import simulate_test_objects
    from tactile_manip.data import save_dataset

    return save_dataset(tmp_path_factory.mktemp("bench") / "unseen.npz", simulate_test_objects(DATASET_CONFIG, 1))


@pytest.fixture(scope="session")
def tiny_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A seeded, untrained ``small`` model with 200x200 output exported to RUN/model.onnx, its checkpoint at
    RUN/best.pt (as a training run leaves them). Its output depends on the reading (not all zero)."""
    torch = pytest.importorskip("torch", reason=TORCH_MISSING)
    pytest.importorskip("onnx", reason="exporting a model needs onnx (pip install -e '.[train]')")
    pytest.importorskip("onnxruntime", reason="running a model needs onnxruntime")
    from tactile_manip.config import to_dict
    from tactile_manip.learning.cvae.export import export_onnx
    from tactile_manip.learning.cvae.model import SuperMagCVAE, preset

    run = tmp_path_factory.mktemp("run")
    torch.manual_seed(0)
    model = SuperMagCVAE(preset("small")).eval()
    with torch.no_grad():  # an untrained decoder outputs zeros through its ReLU; make the output input-dependent
        for mod in model.decoder.mod:
            torch.nn.init.normal_(mod.proj.weight, std=1.0)
        model.decoder.head.bias[0] = 0.3
    torch.save({"model": model.state_dict(), "model_config": to_dict(model.cfg),
                "input": {"clamp_ut": 500.0, "axes": "xyz"}, "train_config": {"preset": "small", "epochs": 1},
                "data_fingerprint": "test"}, run / "best.pt")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        export_onnx(run / "best.pt", run / "model.onnx", pixel_mm=0.1)
    return run / "model.onnx"
