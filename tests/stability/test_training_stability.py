"""Training with extreme learning rates stops with a clear message and never leaves a NaN model behind.

Expected behaviours:
- ``lr`` (or the cosine schedule's end ``lr_min``) of 1e3 or 1e6 is refused before any training: a
  ``ValueError`` naming the field and the allowed range (a ``ConfigError`` from a TOML file, one line at the
  CLI), and nothing is written;
- the largest allowed ``lr`` (0.99) diverges: a ``TrainingError`` saying "diverged", "NaN", the epoch, the step
  and the lr, raised before that epoch's checkpoint is written; every checkpoint left in the folder has finite
  weights and BatchNorm statistics and comes from an earlier epoch;
- a finite model whose validation output is NaN is not saved either.

Already covered in tests/learning/test_train.py: lr = 0.99 raises a TrainingError matching "lower lr", and
lr 0 / NaN are refused. The tiny dataset here is smaller still (18 training pairs of 16x16 px).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from checks import TORCH_MISSING, assert_one_line_error

pytest.importorskip("torch", reason=TORCH_MISSING)
import torch

from tactile_manip.cli import main
from tactile_manip.errors import ConfigError
from tactile_manip.learning.cvae import train as train_module
from tactile_manip.learning.cvae.train import TrainConfig, TrainingError, load_train_config, train, with_overrides
from tactile_manip.data import PairedDataset, depth_image_spec, quantise_depth, save_dataset

TINY = dict(preset="small", batch_size=8, epochs=4, patience=50, threads=1, seed=0, weight_decay=0.0)
STEPS_PER_EPOCH = 2  # 18 training pairs in batches of 8
DIVERGED = re.compile(r"training diverged: .*NaN or infinite.* in epoch (\d+)(?:, step (\d+))? \(lr ([0-9.e+-]+)\)")


def _tiny_dataset(n_per_object: int = 12, size: int = 16) -> PairedDataset:
    """Blobs whose position and size follow the reading; 2 objects x 9 train, 3 val; a third object is test."""
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:size, 0:size]
    fields, depths, obj, splits = [], [], [], []
    for k in range(3):
        for i in range(n_per_object):
            cx, cy, r = rng.uniform(0.3, 0.7, 2).tolist() + [rng.uniform(1.5, 3.0)]
            depths.append(quantise_depth(np.clip(1.5 - ((xx - cx * size) ** 2 + (yy - cy * size) ** 2) / (2 * r * r),
                                                 0, None)))
            f = np.zeros((4, 4, 3), np.float32)
            f[..., 0], f[..., 1], f[..., 2] = (cx - 0.5) * 400, (cy - 0.5) * 400, r * 40
            fields.append(f)
            obj.append(k)
            splits.append("test" if k == 2 else ("val" if i >= n_per_object * 3 // 4 else "train"))
    n = len(fields)
    return PairedDataset(
        readings=np.asarray(fields), images=np.asarray(depths), split=np.array(splits),
        image=depth_image_spec(1.25), object_index=np.asarray(obj, np.int16),
        object_names=np.array(["allen_key", "letter_r", "cylinder_3mm"]),
        extras={"pose": np.zeros((n, 5), np.float32), "force_n": np.full(n, 10.0, np.float32)})


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    return save_dataset(tmp_path_factory.mktemp("stability_data") / "tiny.npz", _tiny_dataset())


def _assert_no_nan_model(out: Path, *, before_epoch: int) -> list[Path]:
    """Every checkpoint in ``out`` is finite (weights, BatchNorm statistics, optimizer state) and older than
    ``before_epoch``; no half-written file is left; the history holds only finite losses."""
    assert not list(out.glob("*.partial"))
    checkpoints = sorted(out.glob("*.pt"))
    for path in checkpoints:
        payload = torch.load(path, map_location="cpu", weights_only=True)
        assert payload["state"]["epoch"] < before_epoch, path
        tensors = list(payload["model"].values())
        for state in payload["optimizer"]["state"].values():
            tensors += [t for t in state.values() if torch.is_tensor(t)]
        assert all(torch.isfinite(t).all() for t in tensors if t.is_floating_point()), path
    if (out / "history.json").exists():
        history = json.loads((out / "history.json").read_text())["history"]
        assert all(row["epoch"] < before_epoch and math.isfinite(row["loss"]) and math.isfinite(row["val_mse"])
                   for row in history)
    return checkpoints


# ---------------------------------------------------------------- refused before training


@pytest.mark.parametrize("lr", [1e3, 1e6, 1.0, math.inf, -1e3])
def test_extreme_learning_rates_are_refused_before_any_training(lr):
    with pytest.raises(ValueError, match=re.escape(f"lr must be in (0, 1), got {float(lr)}")):
        TrainConfig(**{**TINY, "lr": lr})
    with pytest.raises(ValueError, match=r"lr must be in \(0, 1\)"):  # the CLI's override path
        with_overrides(TrainConfig(**TINY), lr=lr)


@pytest.mark.parametrize("lr_min", [1e3, 1e6, math.nan, -1.0])
def test_an_extreme_end_of_the_cosine_schedule_is_refused(lr_min):
    """lr_min was unchecked: lr_min = 1e6 trained at lr 1e6 in the last epoch and saved a model whose
    validation output was NaN, without an error."""
    with pytest.raises(ValueError, match=r"lr_min must be in \[0, 1\), got"):
        TrainConfig(**{**TINY, "lr_schedule": "cosine", "lr_min": lr_min})


@pytest.mark.parametrize("key, value", [("lr", "1e6"), ("lr_min", "1e3")])
def test_a_config_file_with_an_extreme_rate_is_one_clear_line_at_the_cli(tmp_path, data, capsys, key, value):
    config = tmp_path / "extreme.toml"
    config.write_text(f'preset = "small"\nepochs = 2\nlr_schedule = "cosine"\n{key} = {value}\n')
    with pytest.raises(ConfigError, match=rf"{key} must be in"):
        load_train_config(config)
    out = tmp_path / "run"
    assert main(["train", "--config", str(config), "--data", str(data), "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", f"{key} must be in", str(config))
    assert not out.exists()  # nothing written, let alone a NaN model


def test_asking_for_a_gpu_that_is_not_there_is_one_clear_line(tmp_path, data, capsys, monkeypatch):
    config = tmp_path / "tiny.toml"
    config.write_text('preset = "small"\nepochs = 1\nbatch_size = 8\nthreads = 1\n')
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    out = tmp_path / "run"
    assert main(["train", "--config", str(config), "--data", str(data), "--out", str(out), "--device", "cuda"]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", "no CUDA GPU", "cpu")
    assert not out.exists()
    assert main(["train", "--config", str(config), "--data", str(data), "--out", str(out), "--device", "cpu",
                 "--max-minutes", "5"]) == 0
    summary = json.loads((out / "history.json").read_text())
    assert summary["device"] == "cpu" and summary["train_config"]["max_minutes"] == 5.0


# ---------------------------------------------------------------- divergence during training


@pytest.mark.parametrize("lr, good_epochs", [(0.99, False), (0.2, True)])
def test_a_diverging_learning_rate_stops_with_a_clear_message_and_no_nan_model(data, tmp_path, lr, good_epochs):
    """0.99 (the largest allowed) diverges in its first epoch: nothing is saved. 0.2 trains one good epoch
    first: its checkpoints stay, finite, and the diverged epoch writes none."""
    with pytest.raises(TrainingError) as info:
        train(TrainConfig(**{**TINY, "lr": lr, "epochs": 6}), data, tmp_path)
    message = str(info.value)
    match = DIVERGED.search(message)
    assert match and match.group(2), message  # epoch and step
    assert float(match.group(3)) == lr and "lower lr" in message
    checkpoints = _assert_no_nan_model(tmp_path, before_epoch=int(match.group(1)))
    assert bool(checkpoints) == good_epochs


def test_a_nan_loss_mid_epoch_names_epoch_step_and_lr_and_keeps_the_last_good_checkpoint(data, tmp_path,
                                                                                         monkeypatch):
    """Fault injection: the loss of epoch 2, step 2 is NaN (as an overflow would make it)."""
    real, calls = train_module.negative_elbo, []

    def poisoned(*args, **kwargs):
        loss, stats = real(*args, **kwargs)
        calls.append(1)
        return (loss * math.nan if len(calls) == STEPS_PER_EPOCH + 2 else loss), stats

    monkeypatch.setattr(train_module, "negative_elbo", poisoned)
    # the cosine schedule over 4 epochs: epoch 2 runs at 1e-4 + 0.5 (2e-3 - 1e-4)(1 + cos(pi/3)) = 1.525e-3
    cfg = TrainConfig(**{**TINY, "lr": 2e-3, "lr_schedule": "cosine", "lr_min": 1e-4})
    with pytest.raises(TrainingError, match=re.escape("in epoch 2, step 2 (lr 0.001525)")) as info:
        train(cfg, data, tmp_path)
    assert "diverged" in str(info.value) and "nan" in str(info.value)
    assert len(calls) == STEPS_PER_EPOCH + 2  # it stopped at the bad step, before its update
    assert {p.name for p in _assert_no_nan_model(tmp_path, before_epoch=2)} == {"checkpoint.pt", "best.pt"}


def test_a_finite_model_with_nan_validation_output_is_not_saved(data, tmp_path, monkeypatch):
    """Fault injection: epoch 2's weights stay finite but the validation output overflows to NaN (what
    lr 1e6 did through lr_min). Expected: a TrainingError before epoch 2's checkpoint is written."""
    real = train_module.evaluate_split
    epochs = iter(range(1, 100))

    def overflowing(*args, **kwargs):
        out = real(*args, **kwargs)
        return {"mse": math.nan, "psnr": math.nan} if next(epochs) == 2 else out

    monkeypatch.setattr(train_module, "evaluate_split", overflowing)
    with pytest.raises(TrainingError, match=r"diverged: the validation error \(nan\) became NaN or infinite in "
                                            r"epoch 2 \(lr 0\.002\)"):
        train(TrainConfig(**{**TINY, "lr": 2e-3}), data, tmp_path)
    assert _assert_no_nan_model(tmp_path, before_epoch=2)  # epoch 1's checkpoint survives


def test_the_cli_reports_divergence_in_one_line(data, tmp_path, capsys):
    config = tmp_path / "hot.toml"
    config.write_text('preset = "small"\nepochs = 6\nbatch_size = 8\nlr = 0.99\nweight_decay = 0.0\n'
                      'patience = 50\nthreads = 1\n')
    out = tmp_path / "run"
    assert main(["train", "--config", str(config), "--data", str(data), "--out", str(out)]) == 2
    line = assert_one_line_error(capsys.readouterr().err, "train", "lr 0.99", after_progress=True)
    match = DIVERGED.search(line)
    assert match, line
    _assert_no_nan_model(out, before_epoch=int(match.group(1)))
