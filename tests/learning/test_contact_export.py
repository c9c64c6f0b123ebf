"""Export of the contact network: the ONNX file computes what torch does and carries what inference needs."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="export needs torch")
onnx = pytest.importorskip("onnx", reason="export needs onnx")
ort = pytest.importorskip("onnxruntime", reason="the parity check runs onnxruntime")

from tactile_manip.cli import main  # noqa: E402
from tactile_manip.learning.contact.export import load_contact_checkpoint  # noqa: E402
from tactile_manip.learning.contact.model import FusedContactModel  # noqa: E402
from tactile_manip.learning.contact.train import dataset_windows  # noqa: E402
from tactile_manip.perception.reconstruct import METADATA_KEY  # noqa: E402


def _metadata(path) -> dict:
    props = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
    return json.loads(props[METADATA_KEY])


def test_onnx_matches_torch_on_real_windows(contact_model_files, labelled_presses) -> None:
    _, run, model_path = contact_model_files
    model, payload = load_contact_checkpoint(run / "best.pt")
    windows = dataset_windows(labelled_presses(), payload["input"]["context"])[-100:]
    with torch.no_grad():
        mean, sigma = (t.numpy() for t in model(torch.from_numpy(windows)))
    got_mean, got_sigma = ort.InferenceSession(str(model_path)).run(None, {"field_ut": windows})
    np.testing.assert_allclose(got_mean, mean, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(got_sigma, sigma, rtol=1e-4, atol=1e-5)


def test_the_fused_graph_is_the_same_function_as_the_members(contact_model_files) -> None:
    _, run, _ = contact_model_files
    model, _ = load_contact_checkpoint(run / "best.pt")
    x = torch.from_numpy(np.random.default_rng(0).normal(0, 300, (16, 3, 3, 3, 3)).astype(np.float32))
    with torch.no_grad():
        for a, b in zip(model(x), FusedContactModel(model)(x)):  # float32, summed in another order: ~3e-5 apart
            np.testing.assert_allclose(a.numpy(), b.numpy(), rtol=1e-4, atol=1e-5)


def test_the_file_carries_targets_units_layout_context_and_normalisation(contact_model_files) -> None:
    _, run, model_path = contact_model_files
    meta = _metadata(model_path)
    assert meta["kind"] == "contact"
    assert meta["targets"] == {"names": ["x_mm", "y_mm", "force_n"], "units": ["mm", "mm", "N"]}
    assert meta["board_layout"] == "anyskin-5"
    assert meta["input"]["shape"] == ["batch", 3, 3, 3, 3]
    assert meta["context"]["frames"] == 3 and meta["context"]["max_gap_s"] == 1.0
    norm = meta["normalisation"]
    assert len(norm["feature_offset"]) == len(norm["feature_scale"]) == 27 + 28 + 2 * 27
    assert len(norm["target_scale"]) == 3 and min(norm["target_scale"]) > 0
    assert set(meta["training_data"]["val_rmse"]) == {"x_mm", "y_mm", "force_n"}


def test_export_cli_writes_a_checked_file_and_refuses_image_options(contact_model_files, tmp_path, capsys) -> None:
    data_path, run, _ = contact_model_files
    out = tmp_path / "m.onnx"
    assert main(["export", "--checkpoint", str(run / "best.pt"), "--out", str(out), "--data", str(data_path)]) == 0
    assert "contact model" in capsys.readouterr().out and out.is_file()
    assert main(["export", "--checkpoint", str(run / "best.pt"), "--out", str(tmp_path / "n.onnx"),
                 "--card", str(tmp_path / "card.md")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--card" in err[0]
    assert not (tmp_path / "n.onnx").exists()


def test_an_undertrained_model_exports_too(contact_model_files, tmp_path) -> None:
    # after one epoch the sigmas of random windows run to hundreds of target spreads: float32 rounding there
    # is relative to the value, not a mismatch between ONNX and torch
    from tactile_manip.learning.contact.export import export_contact_onnx
    from tactile_manip.learning.contact.train import ContactTrainConfig, train_contact

    data, _, _ = contact_model_files
    train_contact(ContactTrainConfig(hidden=32, members=2, epochs=1, patience=1, batch_size=64, lr=5e-3, threads=1),
                  [data], tmp_path / "run")
    meta = export_contact_onnx(tmp_path / "run" / "best.pt", tmp_path / "early.onnx")
    assert (tmp_path / "early.onnx").is_file() and meta["parity_max_abs"] <= 1e-4
