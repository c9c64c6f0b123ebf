"""Training of the contact network: it learns, keeps its normalisation and context, validates on a tail."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="training needs torch")

from tactile_manip.config import load_config  # noqa: E402
from tactile_manip.errors import ConfigError, DatasetError  # noqa: E402
from tactile_manip.learning.contact.export import load_contact_checkpoint  # noqa: E402
from tactile_manip.learning.contact.train import (ContactTrainConfig, dataset_windows, split_indices,  # noqa: E402
                                                  train_contact)


def test_the_trained_model_beats_the_mean_on_every_target(contact_model_files, labelled_presses) -> None:
    data_path, run, _ = contact_model_files
    history = json.loads((run / "history.json").read_text())
    data = labelled_presses()
    spread = data.targets[data.indices("train")].std(0)
    for k, name in enumerate(data.target_names):
        assert history["val_rmse"][name] < 0.5 * spread[k], (name, history["val_rmse"][name], spread[k])


def test_the_checkpoint_holds_normalisation_context_and_target_names(contact_model_files, labelled_presses) -> None:
    _, run, _ = contact_model_files
    model, payload = load_contact_checkpoint(run / "best.pt")
    assert payload["targets"] == ["x_mm", "y_mm", "force_n"]
    assert payload["input"]["layout"] == "anyskin-5"
    assert payload["input"]["context"]["frames"] == 3
    assert payload["input"]["context"]["frame_period_s"] == pytest.approx(0.05)
    data = labelled_presses()
    train, _ = split_indices(data, 0.1)
    np.testing.assert_allclose(model.target_offset.numpy(), data.targets[train].mean(0), rtol=1e-4, atol=1e-4)
    assert (model.feature_scale > 0).all()


def test_sigma_is_positive_and_the_mixture_mean_is_the_members_mean(contact_model_files, labelled_presses) -> None:
    _, run, _ = contact_model_files
    model, payload = load_contact_checkpoint(run / "best.pt")
    data = labelled_presses()
    windows = torch.from_numpy(dataset_windows(data, payload["input"]["context"])[:50])
    with torch.no_grad():
        mean, sigma = model(windows)
        z = model.standardised_features(windows)
        members = torch.stack([m(z)[0] for m in model.members]).mean(0)
    assert (sigma > 0).all() and torch.isfinite(sigma).all()
    np.testing.assert_allclose(mean.numpy(), (model.target_offset + model.target_scale * members).numpy(), rtol=1e-5,
                               atol=1e-4)


def test_the_validation_tail_is_the_end_of_each_runs_training_rows_in_time(labelled_presses) -> None:
    data = labelled_presses(200)
    train, val = split_indices(data, 0.1)
    assert len(val) == 16 and len(train) == 144
    assert val.min() > train.max()
    assert not set(val) & set(data.indices("test"))


def test_context_frames_are_earlier_rows_of_the_same_run(labelled_presses) -> None:
    data = labelled_presses(20)
    w = dataset_windows(data, {"frames": 3, "max_gap_s": 1.0})
    assert w.shape == (20, 3, 3, 3, 3)
    np.testing.assert_array_equal(w[5, 1], data.readings[4])
    np.testing.assert_array_equal(w[5, 2], data.readings[3])
    np.testing.assert_array_equal(w[0, 1], data.readings[0])  # nothing before the first row: itself


def test_config_values_are_checked() -> None:
    with pytest.raises(ValueError, match="members"):
        ContactTrainConfig(members=0)
    with pytest.raises(ValueError, match="val_fraction"):
        ContactTrainConfig(val_fraction=1.5)
    with pytest.raises(ValueError, match="features"):
        ContactTrainConfig(features="pixels")


def test_the_shipped_config_loads_and_refuses_unknown_keys(tmp_path) -> None:
    cfg = load_config("configs/train/contact.toml", ContactTrainConfig)
    assert cfg.kind == "contact" and cfg.members >= 1
    bad = tmp_path / "bad.toml"
    bad.write_text('kind = "contact"\nmembrs = 3\n')
    with pytest.raises(ConfigError, match="membrs"):
        load_config(bad, ContactTrainConfig)


def test_the_known_probe_config_is_the_supermag_network_with_its_own_epochs() -> None:
    probe = load_config("configs/train/contact_probe.toml", ContactTrainConfig)
    supermag = load_config("configs/train/contact_supermag.toml", ContactTrainConfig)
    assert probe.context_frames == 1 and probe.threads == 1
    assert dataclasses.replace(probe, epochs=supermag.epochs, patience=supermag.patience) == supermag


def test_unknown_targets_and_image_only_data_are_refused(tmp_path, labelled_presses) -> None:
    from tactile_manip.data import save_dataset

    save_dataset(tmp_path / "d.npz", labelled_presses(40))
    with pytest.raises(ConfigError, match="shear_x_n"):
        train_contact(ContactTrainConfig(targets=["shear_x_n"], epochs=1), [tmp_path / "d.npz"], tmp_path / "run")
    assert not (tmp_path / "run" / "best.pt").exists()
    images_only = dataclasses.replace(labelled_presses(40), images=np.zeros((40, 8, 8), np.float32), targets=None,
                                      target_names=())
    save_dataset(tmp_path / "images.npz", images_only)
    with pytest.raises(DatasetError, match="images only"):
        train_contact(ContactTrainConfig(epochs=1), [tmp_path / "images.npz"], tmp_path / "run2")


def test_sigma_is_scaled_so_that_68_percent_of_validation_errors_are_within_one_sigma(contact_model_files,
                                                                                       labelled_presses) -> None:
    _, run, _ = contact_model_files
    model, payload = load_contact_checkpoint(run / "best.pt")
    data = labelled_presses()
    _, val = split_indices(data, 0.1)
    windows = torch.from_numpy(dataset_windows(data, payload["input"]["context"])[val])
    with torch.no_grad():
        mean, sigma = model(windows)
    inside = ((mean - torch.from_numpy(data.targets[val])).abs() <= sigma).float().mean(0)
    np.testing.assert_allclose(inside.numpy(), 0.683, atol=0.03)
    assert (model.sigma_scale > 0).all() and not torch.equal(model.sigma_scale, torch.ones(3))


def test_the_sigma_map_holds_68_percent_in_each_part_of_the_models_sigma(contact_model_files,
                                                                          labelled_presses) -> None:
    from tactile_manip.learning.contact.train import SIGMA_MAP_RUN, fit_sigma_maps
    from tactile_manip.perception.confidence import SigmaCalibration

    _, run, _ = contact_model_files
    model, payload = load_contact_checkpoint(run / "best.pt")
    data = labelled_presses(n=1200, seed=4)
    windows = torch.from_numpy(dataset_windows(data, payload["input"]["context"]))
    targets = torch.from_numpy(data.targets)
    maps = fit_sigma_maps(model, windows, targets, list(payload["targets"]))
    assert set(maps) == {"x_mm", "y_mm", "force_n"}
    with torch.no_grad():
        mean, sigma = model(windows)
    err = (mean - targets).abs().numpy()
    for k, name in enumerate(payload["targets"]):
        cal = SigmaCalibration.from_dict(maps[name])
        assert cal.samples == 1200 and len(cal.knots) >= 2
        raw = sigma[:, k].numpy()
        inside = err[:, k] <= cal(raw)
        # the fitted samples: 68.3 % overall, and in the lower and the upper half of the model's sigma alike
        low = raw <= np.median(raw)
        assert abs(inside.mean() - 0.683) < 0.04
        assert abs(inside[low].mean() - 0.683) < 0.08 and abs(inside[~low].mean() - 0.683) < 0.08
    # a validation tail shorter than two runs keeps the global scale only: the fixture's model has no map
    assert 0.1 * 0.8 * 600 < 2 * SIGMA_MAP_RUN and payload.get("sigma_calibration") == {}
