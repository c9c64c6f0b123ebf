"""Labels for a pad's presses from its twin's simulated presses, read backwards and corrected by a few labels."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from tactile_manip.errors import ConfigError, DatasetError
from tactile_manip.learning.contact.twin_prior import check_bank_targets, twin_labels, twin_targets


def _bank(labelled_presses, *, turn=None, offset=(0.0, 0.0), force_gain=1.0):
    """A twin's presses of the synthetic pad: its readings and targets (x_mm, y_mm, force_n), the places given in
    a frame turned by ``turn`` (2x2) and shifted by ``offset``, the force scaled by ``force_gain``."""
    bank = labelled_presses(3000, seed=7)
    t = bank.targets.astype(np.float64).copy()
    if turn is not None:
        t[:, :2] = t[:, :2] @ np.asarray(turn, float).T
    t[:, :2] += offset
    t[:, 2] *= force_gain
    return bank.readings, t, list(bank.target_names)


def _mask(n, k, seed=0):
    lab = np.zeros(n, bool)
    lab[np.random.default_rng(seed).choice(n, k, replace=False)] = True
    return lab


def _rmse(a, b):
    return float(np.sqrt(np.mean(np.sum((np.asarray(a) - np.asarray(b)) ** 2, axis=-1))))


def test_a_faithful_twin_places_every_press_with_no_label(labelled_presses) -> None:
    data = labelled_presses(600)
    readings, targets, names = _bank(labelled_presses)
    y = data.targets.astype(np.float64)
    found = twin_labels(data.readings, y, np.zeros(len(data), bool), bank_readings=readings, bank_targets=targets,
                        names=names, bank_names=names)
    strong = y[:, 2] > 2.0  # a press of almost no force has almost no field to read a place from
    assert _rmse(found.values[strong, :2], y[strong, :2]) < 1.0    # on a 10 x 10 mm pad
    assert found.methods == ("twin, refined on the field model",) * 2 + ("twin",) and np.isnan(found.loo_rmse).all()
    spread = _rmse(y[strong, :2], y[strong, :2].mean(axis=0))
    assert _rmse(found.values[strong, :2], y[strong, :2]) < 0.25 * spread


@pytest.mark.parametrize("mixing", [0.0, 0.03])
def test_with_no_label_the_twin_s_places_are_refitted_on_the_real_field(labelled_presses, mixing) -> None:
    # a twin read backwards places each press where the twin's detail is like the reading; a smooth model of the
    # real readings at those places takes that scatter out, for a faithful twin and for one whose readouts mix
    # the channels by a few per cent
    data = labelled_presses(600)
    readings, targets, names = _bank(labelled_presses)
    flat = readings.reshape(len(readings), -1)
    mix = np.eye(flat.shape[1]) + mixing * np.random.default_rng(3).standard_normal((flat.shape[1],) * 2)
    readings = (flat @ mix).reshape(readings.shape)
    y = data.targets.astype(np.float64)
    none = np.zeros(len(data), bool)
    raw, refined = (twin_labels(data.readings, y, none, bank_readings=readings, bank_targets=targets, names=names,
                                bank_names=names, refine=refine) for refine in (False, True))
    strong = y[:, 2] > 2.0
    assert raw.methods[0] == "twin" and refined.methods[0] == "twin, refined on the field model"
    assert _rmse(refined.values[strong, :2], y[strong, :2]) < 0.9 * _rmse(raw.values[strong, :2], y[strong, :2])
    np.testing.assert_array_equal(refined.values[:, 2], raw.values[:, 2])  # the load is the twin's, as it was


def test_labels_turn_and_shift_the_twin_s_pad_frame_onto_the_rig_s(labelled_presses) -> None:
    data = labelled_presses(600)
    y = data.targets.astype(np.float64)
    readings, targets, names = _bank(labelled_presses, turn=[[0, -1], [1, 0]], offset=(40.0, -12.0))
    lab = _mask(len(data), 25)
    none = twin_labels(data.readings, y[:, :2], np.zeros(len(data), bool), bank_readings=readings,
                       bank_targets=targets, names=names[:2], bank_names=names)
    found = twin_labels(data.readings, y[:, :2], lab, bank_readings=readings, bank_targets=targets,
                        names=names[:2], bank_names=names, refine=False)  # the correction alone (refit: below)
    strong = (y[:, 2] > 2.0) & ~lab
    assert _rmse(none.values[strong], y[strong, :2]) > 20.0     # the twin's own frame
    assert _rmse(found.values[strong], y[strong, :2]) < 1.0     # the rig's, from 25 labels
    assert found.methods[0].startswith("twin place, ") and found.methods[0] == found.methods[1]
    np.testing.assert_array_equal(found.values[lab], y[lab, :2])
    assert found.loo_rmse.shape == (2,) and np.all(found.loo_rmse < 1.5)


def test_labels_correct_a_twin_whose_force_is_off_by_a_gain(labelled_presses) -> None:
    data = labelled_presses(600)
    y = data.targets.astype(np.float64)
    readings, targets, names = _bank(labelled_presses, force_gain=2.0)
    lab = _mask(len(data), 25, seed=2)
    none = twin_labels(data.readings, y[:, 2:], np.zeros(len(data), bool), bank_readings=readings,
                       bank_targets=targets, names=["force_n"], bank_names=names)
    found = twin_labels(data.readings, y[:, 2:], lab, bank_readings=readings, bank_targets=targets,
                        names=["force_n"], bank_names=names)
    assert _rmse(found.values[~lab], y[~lab, 2:]) < 0.3 * _rmse(none.values[~lab], y[~lab, 2:])
    assert np.isfinite(found.loo_rmse).all()


def test_what_the_twin_cannot_label_is_refused(labelled_presses) -> None:
    data = labelled_presses(200)
    readings, targets, names = _bank(labelled_presses)
    y = data.targets.astype(np.float64)
    none = np.zeros(len(data), bool)
    with pytest.raises(DatasetError, match="no target y_mm"):
        twin_labels(data.readings, y[:, :1], none, bank_readings=readings, bank_targets=targets,
                    names=["y_mm"], bank_names=["x_mm", "v_mm", "force_n"])
    with pytest.raises(DatasetError, match="readings of 18 values against the twin's bank of 27"):
        twin_labels(data.readings[:, :2], y, none, bank_readings=readings, bank_targets=targets, names=names,
                    bank_names=names)
    with pytest.raises(DatasetError, match="2 labelled press.*3 or more"):
        twin_labels(data.readings, y, _mask(len(data), 2), bank_readings=readings, bank_targets=targets,
                    names=names, bank_names=names)
    with pytest.raises(DatasetError, match="at least 8"):
        twin_targets(data.readings, readings[:5], targets[:5])
    with pytest.raises(DatasetError, match="not grip_n"):
        check_bank_targets(["x_mm", "grip_n"])


@pytest.fixture(scope="module")
def twin_runs(tmp_path_factory, labelled_presses):
    """(folder, summary with 20 labels and the twin, summary with none) of a tiny network."""
    pytest.importorskip("torch", reason="training needs torch")
    from tactile_manip.data import from_arrays, save_dataset
    from tactile_manip.data.dataset import UNLABELLED
    from tactile_manip.learning.contact.train import ContactTrainConfig, train_contact

    root = tmp_path_factory.mktemp("twin")
    readings, targets, names = _bank(labelled_presses)
    save_dataset(root / "twin.npz", from_arrays(readings, targets=dict(zip(names, targets.T)),
                                                provenance={"layout": "anyskin-5"}))
    data = labelled_presses(500)
    train = np.flatnonzero(data.split == "train")
    for keep in (20, 0):
        hide = np.setdiff1d(train, np.random.default_rng(0).choice(train, keep, replace=False))
        split = data.split.astype("U10")
        split[hide] = UNLABELLED
        t = data.targets.copy()
        t[hide] = np.nan
        save_dataset(root / f"k{keep}.npz", dataclasses.replace(data, split=split, targets=t))
    cfg = ContactTrainConfig(targets=["x_mm", "y_mm"], hidden=32, members=1, epochs=20, patience=20, batch_size=64,
                             lr=5e-3, threads=1, unlabelled="twin")
    few = train_contact(cfg, [root / "k20.npz"], root / "few", prior=root / "twin.npz")
    zero = train_contact(cfg, [root / "k0.npz"], root / "zero", prior=root / "twin.npz")
    return root, few, zero


def test_training_on_the_twin_s_labels_records_them_and_the_prior(twin_runs) -> None:
    root, few, zero = twin_runs
    assert few["pseudo_labels"]["labelled"] == 20 and few["pseudo_labels"]["unlabelled"] == 400 - 20
    assert few["train_samples"] + few["val_samples"] == 400
    assert few["prior"]["path"] == str(root / "twin.npz") and few["prior"]["presses"] == 3000
    assert json.loads((root / "few" / "history.json").read_text())["prior"] == few["prior"]
    # no label at all: the twin's answers are the whole training set, and no leave-one-out error widens sigma
    assert zero["pseudo_labels"]["labelled"] == 0 and zero["train_samples"] + zero["val_samples"] == 400
    assert all(np.isnan(v) for v in zero["pseudo_labels"]["loo_rmse"])
    assert all(np.isfinite(v) for v in zero["sigma_scale"])


def test_the_twin_and_its_prior_come_together(twin_runs) -> None:
    from tactile_manip.learning.contact.train import ContactTrainConfig, train_contact

    root, _, _ = twin_runs
    twin = ContactTrainConfig(targets=["x_mm", "y_mm"], hidden=8, members=1, epochs=1, unlabelled="twin")
    with pytest.raises(ConfigError, match="--prior TWIN.npz"):
        train_contact(twin, [root / "k20.npz"], root / "no_prior")
    with pytest.raises(ConfigError, match="--prior only with it"):
        train_contact(dataclasses.replace(twin, unlabelled="manifold"), [root / "k20.npz"], root / "m",
                      prior=root / "twin.npz")


def test_the_twin_recipe_is_the_few_label_recipe_with_the_twin_as_its_labeller() -> None:
    from tactile_manip.config import load_config
    from tactile_manip.learning.contact.train import ContactTrainConfig

    twin = load_config("configs/train/contact_twin.toml", ContactTrainConfig)
    few = load_config("configs/train/contact_fewlabel.toml", ContactTrainConfig)
    assert twin.unlabelled == "twin" and few.unlabelled == "manifold"
    same = ("context_frames", "features", "hidden", "layers", "members", "epochs", "lr", "label_recency")
    assert all(getattr(twin, f) == getattr(few, f) for f in same)


def test_a_twin_of_stage_poses_stands_its_z_in_for_the_force_the_labels_then_fit(labelled_presses) -> None:
    data = labelled_presses(600)
    y = data.targets.astype(np.float64)
    readings, targets, _ = _bank(labelled_presses)
    stage = np.c_[targets[:, :2], 145.0 - 0.3 * targets[:, 2]]  # a deeper press: a smaller stage z
    lab = _mask(len(data), 25, seed=4)
    found = twin_labels(data.readings, y[:, 2:], lab, bank_readings=readings, bank_targets=stage,
                        names=["force_n"], bank_names=["x_mm", "y_mm", "z_mm"])
    assert "twin's z_mm" in found.methods[0]
    assert _rmse(found.values[~lab], y[~lab, 2:]) < 0.25 * y[:, 2].std()
    with pytest.raises(DatasetError, match="gives no force_n of its own.*from the twin's z_mm"):
        twin_labels(data.readings, y[:, 2:], np.zeros(len(data), bool), bank_readings=readings,
                    bank_targets=stage, names=["force_n"], bank_names=["x_mm", "y_mm", "z_mm"])


def test_labels_correct_a_stage_pose_twin_whose_readings_are_off_by_a_smooth_gain(labelled_presses) -> None:
    data = labelled_presses(600)
    y = data.targets.astype(np.float64)
    readings, targets, _ = _bank(labelled_presses)
    gain = 1.0 + 0.6 * np.tanh(targets[:, 0] / 4.0)  # the twin reads weak on one side of the pad, strong on the other
    off = (readings * gain[:, None, None, None] * np.array([1.0, 0.7, 1.0])).astype(np.float32)
    stage = np.c_[targets[:, :2], 145.0 - 0.3 * targets[:, 2]]
    lab = _mask(len(data), 40, seed=5)
    # the correction of the readings alone, without the refit on the real field (which, on this synthetic pad,
    # takes the same error out either way: 0.108 mm with or without the correction)
    found = twin_labels(data.readings, y[:, :2], lab, bank_readings=off, bank_targets=stage,
                        names=["x_mm", "y_mm"], bank_names=["x_mm", "y_mm", "z_mm"], refine=False)
    plain = twin_labels(data.readings, y[:, :2], lab, bank_readings=off, bank_targets=np.c_[stage[:, :2]],
                        names=["x_mm", "y_mm"], bank_names=["x_mm", "y_mm"], refine=False)  # no z: no correction
    strong = (y[:, 2] > 2.0) & ~lab
    assert "readings corrected" in found.methods[0] and "corrected" not in plain.methods[0]
    assert _rmse(found.values[strong], y[strong, :2]) < 0.8 * _rmse(plain.values[strong], y[strong, :2])
    # a twin of the same stage poses in another frame (a quarter turn, shifted) is not corrected at the labels'
    # places, which are not its own
    turned = np.c_[stage[:, :2] @ np.array([[0.0, -1.0], [1.0, 0.0]]).T + [30.0, 5.0], stage[:, 2]]
    other = twin_labels(data.readings, y[:, :2], lab, bank_readings=off, bank_targets=turned,
                        names=["x_mm", "y_mm"], bank_names=["x_mm", "y_mm", "z_mm"], refine=False)
    assert "corrected" not in other.methods[0]
    assert _rmse(other.values[strong], y[strong, :2]) < 1.05 * _rmse(plain.values[strong], y[strong, :2])


def test_the_command_line_refuses_a_prior_where_no_twin_labels_in_one_line(tiny_data, tmp_path, capsys) -> None:
    pytest.importorskip("torch", reason="train needs torch")
    from checks import assert_one_line_error

    from tactile_manip.cli import main

    (tmp_path / "cvae.toml").write_text('preset = "small"\nepochs = 1\n')
    assert main(["train", "--config", str(tmp_path / "cvae.toml"), "--data", str(tiny_data), "--prior",
                 str(tiny_data), "--out", str(tmp_path / "a")]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", "--prior: for a contact model")
    assert main(["train", "--config", "configs/train/contact.toml", "--data", str(tiny_data), "--prior",
                 str(tiny_data), "--out", str(tmp_path / "b")]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", "--prior only with it")
    assert main(["train", "--config", "configs/train/angle_head.toml", "--data", str(tiny_data), "--prior",
                 str(tiny_data), "--out", str(tmp_path / "c")]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", "--prior")
    assert not any((tmp_path / d).exists() for d in "abc")


def test_the_twin_s_load_is_one_term_of_the_norm_s_fit_not_a_route_of_its_own(labelled_presses) -> None:
    data = labelled_presses(600)
    y = data.targets.astype(np.float64)
    readings, targets, names = _bank(labelled_presses)
    lab = _mask(len(data), 25, seed=6)
    noise = np.random.default_rng(6).normal(0, 5.0 * y[:, 2].std(), len(targets))  # a twin whose force says little
    found = twin_labels(data.readings, y[:, 2:], lab, bank_readings=readings,
                        bank_targets=np.c_[targets[:, :2], targets[:, 2] + noise], names=["force_n"], bank_names=names)
    assert found.methods[0].startswith("field norm, bent at") and "the twin load" in found.methods[0]
    assert _rmse(found.values[~lab], y[~lab, 2:]) < 0.25 * y[:, 2].std()   # the norm carries it; the twin is shrunk
    bad = targets.copy()
    bad[3, 2] = np.nan
    with pytest.raises(DatasetError, match="bank holds a NaN"):
        twin_labels(data.readings, y[:, 2:], lab, bank_readings=readings, bank_targets=bad, names=["force_n"],
                    bank_names=names)


def test_with_labels_the_twin_s_places_start_the_few_label_recipe_s_refit_beside_its_maps(labelled_presses) -> None:
    # ten labels, a twin in its own pad frame (a quarter turn, shifted): the labels bring its refitted places into
    # theirs, and those places start the recipe's refit beside the starts of its maps of the readings, with the
    # share the leave-one-out on the labels gives them
    from tactile_manip.learning.contact.fewlabel import pseudo_labels

    data = labelled_presses(600)
    y = data.targets.astype(np.float64)
    readings, targets, names = _bank(labelled_presses, turn=[[0, -1], [1, 0]], offset=(40.0, -12.0))
    lab = _mask(len(data), 10)
    maps = pseudo_labels(data.readings, y[:, :2], lab, names=names[:2])
    found = twin_labels(data.readings, y[:, :2], lab, bank_readings=readings, bank_targets=targets,
                        names=names[:2], bank_names=names)
    strong = (y[:, 2] > 2.0) & ~lab
    assert "and the twin place, refitted, turn and offset at 50%" in found.methods[0]   # 0.27 -> 0.18 mm
    assert _rmse(found.values[strong], y[strong, :2]) < 0.8 * _rmse(maps.values[strong], y[strong, :2])
    np.testing.assert_array_equal(found.values[lab], y[lab, :2])
    assert np.all(np.isfinite(found.loo_rmse)) and np.all(found.loo_rmse < 1.0)
