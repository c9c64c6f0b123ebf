"""Chip noise drawn afresh for simulated presses: the clean reading the simulator stores, redraws that match the
stored reading's statistics, presses at the rail kept, and a clear refusal for data without clean readings."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from checks import TORCH_MISSING

from tactile_manip.data import PairedDataset, save_dataset
from tactile_manip.errors import DatasetError
from tactile_manip.learning.noise import ChipNoise
from tactile_manip.sim.dataset import DatasetConfig, ObjectSpec, PoseRanges, generate


@pytest.fixture(scope="module")
def pressed() -> PairedDataset:
    cfg = DatasetConfig(seed=5, images=False, randomise_spread=1.0, validation_fraction=0.25,
                        poses=PoseRanges(tilt_deg=3.0, force_n=(2.0, 15.0)),
                        objects=[ObjectSpec(name="procedural_bar", count=40, variants=4, kwargs={"seed": 1})])
    return generate(cfg, workers=1)


def _z(readings: np.ndarray, noise: ChipNoise) -> np.ndarray:
    """Residuals from the clean reading in units of each press's drift and noise (x, y, z channels)."""
    level = np.sqrt(noise.noise_ut ** 2 + noise.drift_ut[:, None] ** 2)
    return ((readings - noise.clean_ut) / level[:, None, None, :])[~noise.at_rail]


def test_the_stored_reading_is_the_clean_one_through_the_drawn_chips(pressed) -> None:
    noise = ChipNoise.of(pressed, np.arange(len(pressed.readings)))
    assert noise.clean_ut.shape == pressed.readings.shape and noise.clean_ut.dtype == np.float32
    # each press's noise and drift are its drawn sensor's: the residual is one standard normal per channel
    assert 0.9 < _z(pressed.readings, noise).std() < 1.1
    assert np.abs(noise.clean_ut).max() > 10 * noise.noise_ut.max()   # the contact, not noise, makes the reading
    assert len(set(noise.noise_ut[:, 2].round(3))) > 30               # one level per drawn sensor


def test_a_redraw_is_new_noise_of_the_same_size_on_the_same_contact(pressed) -> None:
    noise = ChipNoise.of(pressed, np.arange(len(pressed.readings)))
    a, b = noise.draw(np.random.default_rng(0)), noise.draw(np.random.default_rng(1))
    assert a.dtype == np.float32 and a.shape == pressed.readings.shape
    assert 0.9 < _z(a, noise).std() < 1.1 and abs(_z(a, noise).mean()) < 0.05
    assert not np.allclose(a, b) and not np.allclose(a, pressed.readings)
    step = a / noise.lsb_ut                                             # whole register steps, as a chip reads
    np.testing.assert_allclose(step, np.rint(step), atol=1e-3)


def test_a_press_at_the_rail_keeps_its_stored_reading(pressed) -> None:
    saturated = pressed.extra("saturated").copy()
    saturated[3, 1, 2, 2] = True
    extras = {**pressed.extras, "saturated": saturated}
    noise = ChipNoise.of(dataclasses.replace(pressed, extras=extras), np.arange(len(pressed.readings)))
    drawn = noise.draw(np.random.default_rng(2))
    assert noise.at_rail[3] and noise.at_rail.sum() == 1 + pressed.extra("saturated").reshape(40, -1).any(1).sum()
    np.testing.assert_array_equal(drawn[3], pressed.readings[3])


def test_data_without_clean_readings_is_refused_by_name(pressed, tmp_path) -> None:
    extras = {k: v for k, v in pressed.extras.items() if k != "field_clean_ut"}
    with pytest.raises(DatasetError, match="field_clean_ut.*redraw_noise = false"):
        ChipNoise.of(dataclasses.replace(pressed, extras=extras), np.arange(4))


def test_training_reads_the_presses_through_new_chips(pressed, tmp_path) -> None:
    pytest.importorskip("torch", reason=TORCH_MISSING)
    from tactile_manip.learning.angle_head.train import AngleTrainConfig, train_angle_head

    path = save_dataset(tmp_path / "bars.npz", pressed)
    cfg = AngleTrainConfig(hidden=16, layers=1, epochs=3, batch_size=8, patience=3, threads=1, redraw_noise=True)
    summary = train_angle_head(cfg, [path], tmp_path / "run")
    assert summary["train_config"]["redraw_noise"] and summary["epochs_run"] == 3
    assert np.isfinite([row["loss"] for row in summary["history"]]).all()
    extras = {k: v for k, v in pressed.extras.items() if k != "field_clean_ut"}
    old = save_dataset(tmp_path / "old.npz", dataclasses.replace(pressed, extras=extras))
    with pytest.raises(DatasetError, match="field_clean_ut"):
        train_angle_head(cfg, [old], tmp_path / "run_old")


def test_contact_training_reads_the_presses_of_each_dataset_through_new_chips(pressed, tmp_path) -> None:
    pytest.importorskip("torch", reason=TORCH_MISSING)
    from tactile_manip.data import load_datasets
    from tactile_manip.learning.contact.train import ContactTrainConfig, split_indices, train_contact

    first = save_dataset(tmp_path / "first.npz", pressed)
    second = save_dataset(tmp_path / "second.npz", pressed.subset(np.arange(20, 40)))
    joined = load_datasets([first, second], images=False)
    train_idx, _ = split_indices(joined, 0.1)
    noise = ChipNoise.of(joined, train_idx)
    # each part's presses in the joined train split's order, each with its own part's chip settings: the clean
    # reading of the same press
    np.testing.assert_array_equal(noise.clean_ut, joined.extra("field_clean_ut")[train_idx])
    np.testing.assert_array_equal(noise.stored_ut, joined.readings[train_idx])
    parts = (pressed, pressed.subset(np.arange(20, 40)))
    apart = ChipNoise.concatenate([ChipNoise.of(d, d.indices("train")) for d in parts])
    np.testing.assert_array_equal(noise.noise_ut, apart.noise_ut)
    np.testing.assert_array_equal(noise.drift_ut, apart.drift_ut)
    cfg = ContactTrainConfig(hidden=16, layers=1, members=1, epochs=3, batch_size=8, patience=3, threads=1,
                             context_frames=1, redraw_noise=True, sigma_map=False)
    summary = train_contact(cfg, [first, second], tmp_path / "run")
    assert summary["train_config"]["redraw_noise"] and summary["members"][0]["epochs_run"] == 3
    assert np.isfinite([row["loss"] for row in summary["members"][0]["history"]]).all()
    extras = {k: v for k, v in pressed.extras.items() if k != "field_clean_ut"}
    old = save_dataset(tmp_path / "old.npz", dataclasses.replace(pressed, extras=extras))
    with pytest.raises(DatasetError, match="field_clean_ut"):
        train_contact(cfg, [old], tmp_path / "run_old")
    with pytest.raises(ValueError, match="context_frames = 1"):
        ContactTrainConfig(context_frames=3, redraw_noise=True)
