"""Training and evaluation say the real cause: no training rows, non-finite readings, config sizes beyond any sane
run, a contact model given to ``evaluate`` on a dataset that also holds images."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import numpy as np
import pytest
from checks import TORCH_MISSING, assert_one_line_error

torch = pytest.importorskip("torch", reason=TORCH_MISSING)

from tactile_manip.cli import main  # noqa: E402
from tactile_manip.data import save_dataset  # noqa: E402
from tactile_manip.errors import ConfigError, DatasetError  # noqa: E402
from tactile_manip.learning.angle_head.train import AngleTrainConfig, load_angle_config  # noqa: E402
from tactile_manip.learning.contact.train import ContactTrainConfig, load_contact_config, train_contact  # noqa: E402
from tactile_manip.learning.cvae.train import TrainConfig, load_train_config, train  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
CONTACT_MODEL = ROOT / "models" / "contact_supermag.onnx"
QUICK_CONTACT = 'kind = "contact"\nhidden = 8\nmembers = 1\nepochs = 2\npatience = 2\nthreads = 1\n'
SUPERMAG_TARGETS = ("x_mm", "y_mm", "depth_mm", "force_n", "in_contact")


def test_a_dataset_without_training_rows_says_so(labelled_presses, tmp_path, capsys):
    data = labelled_presses(120)
    path = save_dataset(tmp_path / "all_test.npz", dataclasses.replace(data, split=np.full(len(data), "test")))
    config = tmp_path / "c.toml"
    config.write_text(QUICK_CONTACT)
    assert main(["train", "--config", str(config), "--data", str(path), "--out", str(tmp_path / "run")]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", f"no training rows: every row of {path} is in the test "
                                                            "split")
    assert not (tmp_path / "run" / "best.pt").exists()


def test_non_finite_readings_are_refused_before_contact_training(labelled_presses, tmp_path):
    data = labelled_presses(120)
    readings = data.readings.copy()
    readings[4, 1, 2, 2], readings[9, 1, 2, 2], readings[9, 0, 1, 0] = np.inf, np.nan, -np.inf
    path = save_dataset(tmp_path / "inf.npz", dataclasses.replace(data, readings=readings))
    cfg = ContactTrainConfig(hidden=8, members=1, epochs=2, patience=2, threads=1)
    with pytest.raises(DatasetError) as e:
        train_contact(cfg, [path], tmp_path / "run")
    message = str(e.value)
    assert str(path) in message and "3 NaN or infinite readings in 2 samples" in message
    assert "channel 'z' of cell (1, 2)" in message and "diverged" not in message


def test_non_finite_readings_are_refused_before_image_training(make_synthetic, tmp_path):
    data = make_synthetic(8)
    readings = data.readings.copy()
    readings[2, 0, 3, 1] = np.inf
    path = save_dataset(tmp_path / "inf.npz", dataclasses.replace(data, readings=readings))
    cfg = TrainConfig(preset="small", epochs=1, batch_size=4, threads=1, device="cpu")
    with pytest.raises(DatasetError, match=r"1 NaN or infinite readings in 1 samples .*channel 'y' of cell \(0, 3\)"):
        train(cfg, path, tmp_path / "run")
    assert not (tmp_path / "run" / "best.pt").exists()


@pytest.mark.parametrize("cls, field, value, allowed", [
    (ContactTrainConfig, "context_frames", 1_000_000, "[1, 64]"),
    (ContactTrainConfig, "context_max_gap_s", 1e9, "[0, 3600] s"),
    (ContactTrainConfig, "hidden", 10 ** 7, "[1, 4096]"),
    (ContactTrainConfig, "members", 1000, "[1, 32]"),
    (ContactTrainConfig, "epochs", 10 ** 9, "[1, 100000]"),
    (ContactTrainConfig, "batch_size", 10 ** 8, "[1, 65536]"),
    (AngleTrainConfig, "hidden", 10 ** 6, "[1, 4096]"),
    (TrainConfig, "shard_buffer", 10 ** 5, "[1, 64]"),
    (TrainConfig, "epochs", 0, "[1, 100000]"),
])
def test_config_sizes_beyond_any_sane_run_are_refused_naming_field_value_and_range(cls, field, value, allowed):
    with pytest.raises(ConfigError) as e:
        cls(**{field: value})
    assert f"{field} must be" in str(e.value) and allowed in str(e.value) and f"got {value!r}" in str(e.value)


def test_an_unbounded_config_file_is_one_line_before_any_allocation(labelled_presses, tmp_path, capsys):
    path = save_dataset(tmp_path / "d.npz", labelled_presses(60))
    config = tmp_path / "huge.toml"
    config.write_text(QUICK_CONTACT + "context_frames = 1000000\n")
    assert main(["train", "--config", str(config), "--data", str(path), "--out", str(tmp_path / "run")]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", str(config), "context_frames", "1000000", "[1, 64]")


def test_every_shipped_training_config_still_loads():
    """The recipes in configs/train, beside the shipped models, and those of the studies in experiments/."""
    loaders = {"contact": load_contact_config, "angle_head": load_angle_config}
    files = (sorted((ROOT / "configs" / "train").glob("*.toml")) + sorted((ROOT / "models").glob("*.train.toml"))
             + sorted((ROOT / "experiments").glob("*/*.toml")))
    assert len(files) > 30
    for path in files:
        data = tomllib.loads(path.read_text())
        if "methods" in data and "presentation" in data:  # a study's trial scene (experiments/fast_model/), not a recipe
            continue
        if {"model", "runs", "checkpoints"} & set(data):  # the bench's candidates (experiments/speed_reports/)
            from tactile_manip.bench.candidates import candidates_file, default_models

            references = candidates_file(ROOT / "experiments/model_variants/bench.toml", ROOT, default_models(ROOT))
            assert candidates_file(path, ROOT, references)
            continue
        loaders.get(data.get("kind", "cvae"), load_train_config)(path)


def _images_and_targets(make_synthetic, *, targets: bool):
    """The 4x4 synthetic image dataset, with the shipped contact model's five targets when ``targets``."""
    data = make_synthetic(6)
    if not targets:
        return data
    rng = np.random.default_rng(0)
    n = len(data)
    values = np.column_stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.uniform(0, 1, n),
                              rng.uniform(0, 5, n), rng.integers(0, 2, n)]).astype(np.float32)
    return dataclasses.replace(data, targets=values, target_names=SUPERMAG_TARGETS)


def test_a_contact_model_on_a_dataset_with_images_is_evaluated_as_a_contact_model(make_synthetic, tmp_path, capsys):
    pytest.importorskip("onnxruntime")
    path = save_dataset(tmp_path / "both.npz", _images_and_targets(make_synthetic, targets=True))
    out = tmp_path / "eval"
    assert main(["evaluate", "--data", str(path), "--model", f"C={CONTACT_MODEL}", "--no-baselines",
                 "--out", str(out)]) == 0
    assert (out / "results.json").is_file() and (out / "contact.png").is_file()
    assert "force_n" in capsys.readouterr().out


def test_a_contact_model_on_images_without_labels_is_one_line(make_synthetic, tmp_path, capsys):
    pytest.importorskip("onnxruntime")
    path = save_dataset(tmp_path / "images.npz", _images_and_targets(make_synthetic, targets=False))
    out = tmp_path / "eval"
    assert main(["evaluate", "--data", str(path), "--model", f"C={CONTACT_MODEL}", "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "evaluate", "contact model", str(CONTACT_MODEL),
                          "no per-sample targets")
    assert not (out / "results.json").exists()
