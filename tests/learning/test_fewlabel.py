"""Labels for unlabelled presses from a handful of labelled ones: places on the map of the readings, loads on the
field norm."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from tactile_manip.errors import DatasetError
from tactile_manip.learning.contact.fewlabel import MIN_LABELLED, isomap, pseudo_labels, reading_maps, recency_weights


def _knn_rmse(x, y, lab, k=5):
    """RMSE on the unlabelled rows of a k-nearest-neighbour mean over the labelled rows (the few-label baseline)."""
    xl, yl = x[lab], y[lab]
    d = ((x[~lab][:, None] - xl[None]) ** 2).sum(-1)
    near = np.argsort(d, axis=1)[:, :k]
    return float(np.sqrt(np.mean(np.sum((yl[near].mean(1) - y[~lab]) ** 2, axis=-1))))


def _labelled_mask(n, k, seed=0):
    lab = np.zeros(n, bool)
    lab[np.random.default_rng(seed).choice(n, k, replace=False)] = True
    return lab


def test_25_labels_place_the_other_presses_far_better_than_a_knn_on_them(labelled_presses) -> None:
    data = labelled_presses(900)
    x = data.readings.reshape(len(data), -1)
    xy = data.targets[:, :2].astype(np.float64)
    lab = _labelled_mask(len(data), 25)
    found = pseudo_labels(data.readings, xy, lab)
    err = np.sqrt(np.mean(np.sum((found.values[~lab] - xy[~lab]) ** 2, axis=1)))
    knn = _knn_rmse((x - x.mean(0)) / np.maximum(x.std(0), 1e-9), xy, lab)   # on standardised readings
    assert err < 0.5 * knn, (err, knn, found.methods)
    assert all("map" in m for m in found.methods)          # position comes from the map, not the field norm
    np.testing.assert_array_equal(found.values[lab], xy[lab])  # labels are kept
    assert found.loo_rmse.shape == (2,) and np.all(found.loo_rmse > 0)


def test_target_names_route_a_place_to_the_maps_and_a_load_to_the_field_norm(labelled_presses) -> None:
    data = labelled_presses(600)
    y = data.targets.astype(np.float64)
    lab = _labelled_mask(len(data), 25, seed=3)
    names = list(data.target_names)
    assert names == ["x_mm", "y_mm", "force_n"]
    named = pseudo_labels(data.readings, y, lab, names=names)
    assert [m.split(",")[0].endswith("map") for m in named.methods] == [True, True, False]
    assert named.methods[2].startswith("field norm")
    # an unknown target may take either kind of fit: here the force's field norm, as the lowest leave-one-out
    other = pseudo_labels(data.readings, y[:, 2:], lab, names=["grip_n"])
    assert other.methods == named.methods[2:] and other.loo_rmse[0] == pytest.approx(named.loo_rmse[2])
    with pytest.raises(DatasetError, match="2 target name.*3 target"):
        pseudo_labels(data.readings, y, lab, names=names[:2])


def test_maps_built_once_give_the_labels_of_maps_built_per_call(labelled_presses) -> None:
    data = labelled_presses(400)
    x = data.readings.reshape(len(data), -1).astype(np.float64)
    x = x[:, x.std(axis=0) > 0]
    xy = data.targets[:, :2].astype(np.float64)
    maps = reading_maps(x)
    for seed in (0, 1):  # two draws of labels on one set of maps
        lab = _labelled_mask(len(data), 25, seed=seed)
        shared = pseudo_labels(data.readings, xy, lab, maps=maps)
        own = pseudo_labels(data.readings, xy, lab)
        np.testing.assert_array_equal(shared.values, own.values)
        assert shared.methods == own.methods
    with pytest.raises(DatasetError, match=r"maps of \[399\] rows given for 400 readings"):
        pseudo_labels(data.readings, xy, lab, maps={name: m[1:] for name, m in maps.items()})


def test_a_force_at_one_place_is_fitted_on_the_field_norm() -> None:
    rng = np.random.default_rng(1)
    force = rng.uniform(0, 30, 800)
    direction = rng.normal(size=15)
    readings = (np.sqrt(force)[:, None] * 100 * direction / np.linalg.norm(direction)
                + rng.normal(0, 0.5, (800, 15)))
    lab = _labelled_mask(800, 25, seed=2)
    found = pseudo_labels(readings, force[:, None], lab)
    assert found.methods[0].startswith("field norm")
    assert np.sqrt(np.mean((found.values[~lab, 0] - force[~lab]) ** 2)) < 1.0


def test_the_map_of_a_flat_sheet_is_that_sheet_up_to_a_turn() -> None:
    rng = np.random.default_rng(3)
    uv = rng.uniform(0, 10, (600, 2))
    sheet = np.stack([uv[:, 0], uv[:, 1], np.zeros(600)], 1) @ np.linalg.qr(rng.normal(size=(3, 3)))[0]
    coords = isomap(sheet, 12)[:, :2]
    a = np.hstack([coords, np.ones((600, 1))])
    fit = np.linalg.lstsq(a, uv, rcond=None)[0]
    assert np.sqrt(np.mean((a @ fit - uv) ** 2)) < 0.3   # an affine map recovers the sheet's coordinates


def test_too_few_labels_and_non_finite_input_are_refused() -> None:
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(100, 6)), rng.normal(size=(100, 1))
    with pytest.raises(DatasetError, match=f"at least {MIN_LABELLED}"):
        pseudo_labels(x, y, _labelled_mask(100, MIN_LABELLED - 1))
    lab = _labelled_mask(100, 10)
    bad = y.copy()
    bad[np.flatnonzero(lab)[0]] = np.nan
    with pytest.raises(DatasetError, match="labelled press has a NaN"):
        pseudo_labels(x, bad, lab)
    bad = x.copy()
    bad[3, 2] = np.inf
    with pytest.raises(DatasetError, match="reading is NaN or infinite"):
        pseudo_labels(bad, y, lab)
    with pytest.raises(DatasetError, match="more than 20"):
        pseudo_labels(x[:15], y[:15], lab[:15] | (np.arange(15) < 6))


def _hide_labels(data, keep: int):
    """``data`` with all but ``keep`` of its training rows turned into unlabelled rows (NaN targets)."""
    from tactile_manip.data.dataset import UNLABELLED

    train = np.flatnonzero(data.split == "train")
    hide = np.setdiff1d(train, np.random.default_rng(0).choice(train, keep, replace=False))
    split = data.split.astype("U10")
    split[hide] = UNLABELLED
    targets = data.targets.copy()
    targets[hide] = np.nan
    return dataclasses.replace(data, split=split, targets=targets)


@pytest.fixture(scope="module")
def few_label_runs(tmp_path_factory, labelled_presses):
    """(dataset, summary with unlabelled = "manifold", summary with "ignore") of a tiny network on 30 labels."""
    pytest.importorskip("torch", reason="training needs torch")
    from tactile_manip.data import save_dataset
    from tactile_manip.learning.contact.train import ContactTrainConfig, train_contact

    root = tmp_path_factory.mktemp("fewlabel")
    save_dataset(root / "few.npz", _hide_labels(labelled_presses(700), 30))
    base = ContactTrainConfig(targets=["x_mm", "y_mm"], hidden=32, members=1, epochs=30, patience=30, batch_size=64,
                              lr=5e-3, threads=1)
    manifold = train_contact(dataclasses.replace(base, unlabelled="manifold"), [root / "few.npz"], root / "m")
    # "ignore" leaves the 3 validation presses of the 30 labels: sigma's calibration on them is warned about
    with pytest.warns(UserWarning, match=r"sigma is calibrated on 3 validation sample\(s\), fewer than 20"):
        ignore = train_contact(base, [root / "few.npz"], root / "i")
    return root, manifold, ignore


def test_manifold_training_learns_from_every_training_row_and_records_the_labelling(few_label_runs) -> None:
    root, manifold, ignore = few_label_runs
    pseudo = manifold["pseudo_labels"]
    assert pseudo["labelled"] == 30 and pseudo["unlabelled"] == 560 - 30
    assert manifold["train_samples"] + manifold["val_samples"] == 560
    assert ignore["pseudo_labels"] is None
    assert ignore["train_samples"] + ignore["val_samples"] == 30   # "ignore" leaves the unlabelled rows out
    assert json.loads((root / "m" / "history.json").read_text())["pseudo_labels"] == pseudo
    assert manifold["sigma_calibration"] == {}   # no sigma map is fitted to labels of the map


def test_sigma_is_widened_by_the_labels_own_leave_one_out_error(few_label_runs) -> None:
    from tactile_manip.learning.contact.train import widening

    _, manifold, _ = few_label_runs
    loo = manifold["pseudo_labels"]["loo_rmse"]
    factors = widening(manifold["val_rmse"], loo, manifold["targets"])
    assert all(f > 1 for f in factors)
    assert widening({"a": 3.0}, [4.0], ["a"]) == pytest.approx([5.0 / 3.0])


def test_the_few_label_recipe_is_the_contact_recipe_with_the_unlabelled_presses_mapped() -> None:
    from tactile_manip.config import load_config
    from tactile_manip.learning.contact.train import ContactTrainConfig

    few = load_config("configs/train/contact_fewlabel.toml", ContactTrainConfig)
    full = load_config("configs/train/contact.toml", ContactTrainConfig)
    assert few.unlabelled == "manifold" and full.unlabelled == "ignore"
    assert few.label_recency > 0   # acts on the labeller only, which the full recipe does not run
    assert dataclasses.replace(few, unlabelled="ignore", threads=full.threads, label_recency=0.0) == full


def _hysteretic_presses(cycles: int = 10, per_cycle: int = 80, seed: int = 4):
    """Readings (N, 15), the reading 2 frames earlier (N, 15) and force (N,) of presses at one place that go in
    and out: the force is 2 N lower on the way in than on the way out at the same depth (an elastomer's
    hysteresis), so the field norm alone cannot tell the two."""
    rng = np.random.default_rng(seed)
    phase = np.arange(cycles * per_cycle) / per_cycle % 1.0
    depth = 1.0 - np.abs(2.0 * phase - 1.0)                     # 0 -> 1 -> 0 each cycle
    unloading = phase > 0.5
    force = 30.0 * depth + np.where(unloading, 1.0, -1.0) * 4.0 * depth * (1.0 - depth) * 2.0
    direction = rng.normal(size=15)
    readings = (depth ** 0.8)[:, None] * 2000.0 * direction / np.linalg.norm(direction) + rng.normal(0, 2.0, (len(depth), 15))
    earlier = readings[np.maximum(np.arange(len(depth)) - 2, 0)]
    return readings, earlier, force


def test_the_norm_s_change_tells_loading_from_unloading() -> None:
    readings, earlier, force = _hysteretic_presses()
    lab = _labelled_mask(len(force), 25, seed=5)
    with_change = pseudo_labels(readings, force[:, None], lab, earlier=earlier)
    alone = pseudo_labels(readings, force[:, None], lab)
    err = [float(np.sqrt(np.mean((f.values[~lab, 0] - force[~lab]) ** 2))) for f in (with_change, alone)]
    assert "change" in with_change.methods[0], with_change.methods
    assert not any("change" in m for m in alone.methods)     # without earlier frames the fit is not offered
    assert err[0] < 0.5 * err[1], err                         # the 2 N branches apart are found from 25 labels


def test_the_shrunk_fit_keeps_its_labels_steady_where_the_terms_nearly_outnumber_them() -> None:
    from tactile_manip.learning.contact.fewlabel import _shrunk

    errors = []
    for seed in range(8):  # 12 labels, 9 coefficients: only the free term matters, the others fit noise
        rng = np.random.default_rng(seed)
        z = rng.normal(size=(400, 8))
        y = 3.0 * z[:, 0] + rng.normal(0, 0.3, 400)
        lab = _labelled_mask(400, 12, seed=seed)
        design = np.hstack([np.ones((400, 1)), z])
        plain = design @ np.linalg.lstsq(design[lab], y[lab], rcond=None)[0]
        errors.append([float(np.sqrt(np.mean((p[~lab] - y[~lab]) ** 2))) for p in (_shrunk(z, free=1)(lab, y), plain)])
    shrunk, plain = np.array(errors).T
    assert shrunk.mean() < 0.75 * plain.mean() and np.all(shrunk < 1.05 * plain), errors


def _one_ridge_of_least_leave_one_out(z, lab, y):
    """The shrunk fit as one ridge weight of least leave-one-out error would give it (what averaging replaces)."""
    from tactile_manip.learning.contact.fewlabel import RIDGE, SHRINK

    a = np.hstack([np.ones((len(z), 1)), z])
    penalty = np.r_[0.0, 0.0, np.ones(z.shape[1] - 1)]
    fits = []
    for weight in SHRINK:
        inv = np.linalg.inv(a[lab].T @ a[lab] + np.diag(weight * penalty + RIDGE))
        coef = inv @ a[lab].T @ y[lab]
        held_out = (y[lab] - a[lab] @ coef) / (1.0 - np.einsum("ij,jk,ik->i", a[lab], inv, a[lab]))
        fits.append((float(np.mean(held_out ** 2)), a @ coef))
    return min(fits, key=lambda f: f[0])[1]


def test_the_shrunk_fit_averages_its_ridge_weights_rather_than_betting_on_one() -> None:
    from tactile_manip.learning.contact.fewlabel import _shrunk

    errors = []
    for seed in range(80):  # 8 labels, 6 terms of which 5 matter a little: how much to shrink is a close call
        rng = np.random.default_rng(seed)
        z = rng.normal(size=(400, 6))
        y = 3.0 * z[:, 0] + z[:, 1:] @ (0.3 * rng.choice([-1.0, 1.0], 5)) + rng.normal(0, 0.5, 400)
        lab = _labelled_mask(400, 8, seed=seed)
        errors.append([float(np.sqrt(np.mean((p[~lab] - y[~lab]) ** 2)))
                       for p in (_shrunk(z, free=1)(lab, y), _one_ridge_of_least_leave_one_out(z, lab, y))])
    averaged, picked = np.array(errors).T
    assert averaged.mean() < 0.97 * picked.mean(), (averaged.mean(), picked.mean())
    assert np.all(averaged < 1.25 * picked), errors  # a blend of the fits, never far from the one picked


def test_the_shrunk_fit_of_labels_it_fits_exactly_returns_them_exactly() -> None:
    from tactile_manip.learning.contact.fewlabel import _shrunk

    z = np.random.default_rng(0).normal(size=(200, 4))
    y = 2.0 * z[:, 0] - 1.0  # only the free term: the unshrunk fit holds out with zero error
    lab = _labelled_mask(200, 10)
    np.testing.assert_allclose(_shrunk(z, free=1)(lab, y), y, atol=1e-6)


def test_earlier_frames_of_another_shape_or_not_finite_are_refused() -> None:
    readings, earlier, force = _hysteretic_presses(cycles=2)
    lab = _labelled_mask(len(force), 10)
    with pytest.raises(DatasetError, match="earlier frames"):
        pseudo_labels(readings, force[:, None], lab, earlier=earlier[:, :12])
    bad = earlier.copy()
    bad[5, 0] = np.nan
    with pytest.raises(DatasetError, match="earlier frames"):
        pseudo_labels(readings, force[:, None], lab, earlier=bad)


def test_training_hands_the_labeller_each_press_s_oldest_context_frame_and_the_target_names(labelled_presses,
                                                                                              monkeypatch) -> None:
    pytest.importorskip("torch", reason="training needs torch")
    from tactile_manip.learning.contact import fewlabel
    from tactile_manip.learning.contact.train import ContactTrainConfig, _pseudo_labels, dataset_windows

    data = _hide_labels(labelled_presses(200), 20)
    cfg = ContactTrainConfig(unlabelled="manifold", context_frames=3)
    windows = dataset_windows(data, cfg)
    seen = {}
    real = fewlabel.pseudo_labels

    def spy(readings, targets, labelled, **kwargs):
        seen.update(readings=readings, earlier=kwargs["earlier"], names=kwargs["names"])
        return real(readings, targets, labelled, **kwargs)

    monkeypatch.setattr(fewlabel, "pseudo_labels", spy)
    labels = data.targets.astype(np.float64).copy()
    _pseudo_labels(data, labels, ["x_mm", "y_mm", "force_n"], cfg, windows)
    assert seen["names"] == ["x_mm", "y_mm", "force_n"]
    rows = np.flatnonzero(np.isin(data.split, ["train", "unlabelled"]))
    np.testing.assert_array_equal(seen["earlier"], windows[rows, -1])
    assert not np.array_equal(seen["earlier"], seen["readings"])   # 20 Hz presses: the frames before are context
    single = dataclasses.replace(cfg, context_frames=1)
    _pseudo_labels(data, labels, ["x_mm", "y_mm", "force_n"], single, dataset_windows(data, single))
    assert seen["earlier"] is None


def test_recency_weights_rise_e_fold_per_unit_rate_over_each_run_to_one_at_its_last_press() -> None:
    times = np.array([10.0, 12.0, 14.0, 100.0, 150.0, 200.0, 7.0])
    runs = np.array([0, 0, 0, 1, 1, 1, 2])
    w = recency_weights(times, 2.0, runs)
    np.testing.assert_allclose(w, np.exp([-2.0, -1.0, 0.0, -2.0, -1.0, 0.0, 0.0]))   # a one-press run weighs 1
    np.testing.assert_allclose(recency_weights(times[:3], 0.0), 1.0)
    assert recency_weights(np.arange(5.0), 10.0).min() > 0   # the largest rate a config allows underflows nothing
    with pytest.raises(DatasetError, match="finite times"):
        recency_weights(np.array([0.0, np.nan, 2.0]), 1.0)
    with pytest.raises(ValueError, match="rate"):
        recency_weights(times, -1.0)


def _softening_presses(n: int = 2000, seed: int = 6):
    """Readings (N, 15), force (N,) and time (N,) of presses at one place on a skin that softens: the force for a
    given field falls linearly by 8 % from the first press to the last."""
    rng = np.random.default_rng(seed)
    time = np.arange(n, dtype=np.float64)
    depth = rng.uniform(0.05, 1.0, n)
    direction = rng.normal(size=15)
    readings = depth[:, None] * 1000.0 * direction / np.linalg.norm(direction) + rng.normal(0, 2.0, (n, 15))
    force = 30.0 * depth * (1.0 - 0.08 * time / n) + rng.normal(0, 0.1, n)
    return readings, force, time


def test_weighing_later_labels_more_follows_a_skin_that_softens_to_the_presses_after_them() -> None:
    readings, force, time = _softening_presses()
    tail = time >= 0.8 * len(time)   # labels drawn before; scored on the presses after them
    errs = []
    for seed in range(6):
        lab = np.zeros(len(time), bool)
        lab[np.random.default_rng(seed).choice(np.flatnonzero(~tail), 25, replace=False)] = True
        fits = [pseudo_labels(readings, force[:, None], lab, names=["force_n"], weights=w)
                for w in (None, np.ones(len(time)), recency_weights(time, 2.0))]
        assert "later labels weighted" in fits[2].methods[0]
        assert "weighted" not in fits[0].methods[0]
        np.testing.assert_array_equal(fits[1].values, fits[0].values)   # equal weights weigh nothing
        errs.append([np.sqrt(np.mean((f.values[tail, 0] - force[tail]) ** 2)) for f in (fits[0], fits[2])])
    errs = np.array(errs)
    assert (errs[:, 1] < errs[:, 0]).all() and errs[:, 1].mean() < 0.9 * errs[:, 0].mean(), errs


def test_label_weights_of_another_length_or_not_positive_on_a_labelled_press_are_refused() -> None:
    readings, force, time = _softening_presses(300)
    lab = _labelled_mask(300, 20)
    with pytest.raises(DatasetError, match="label weights"):
        pseudo_labels(readings, force[:, None], lab, names=["force_n"], weights=np.ones(299))
    w = np.ones(300)
    w[np.flatnonzero(lab)[3]] = 0.0
    with pytest.raises(DatasetError, match="label weights"):
        pseudo_labels(readings, force[:, None], lab, names=["force_n"], weights=w)
    w[np.flatnonzero(lab)[3]] = np.nan
    with pytest.raises(DatasetError, match="label weights"):
        pseudo_labels(readings, force[:, None], lab, names=["force_n"], weights=w)
    w = np.full(300, np.nan)
    w[lab] = 1.0 + np.arange(lab.sum())   # the unlabelled rows' weights are not read
    assert np.isfinite(pseudo_labels(readings, force[:, None], lab, names=["force_n"], weights=w).values).all()


def test_training_weighs_the_labels_by_recency_per_run_only_when_the_config_asks(labelled_presses,
                                                                                monkeypatch) -> None:
    pytest.importorskip("torch", reason="training needs torch")
    from tactile_manip.errors import ConfigError
    from tactile_manip.learning.contact import fewlabel
    from tactile_manip.learning.contact.train import ContactTrainConfig, _pseudo_labels, dataset_windows

    data = _hide_labels(labelled_presses(200), 20)
    data = dataclasses.replace(data, groups=(np.arange(200) >= 100).astype(np.int64))   # two runs
    seen = {}
    real = fewlabel.pseudo_labels

    def spy(readings, targets, labelled, **kwargs):
        seen["weights"] = kwargs["weights"]
        return real(readings, targets, labelled, **kwargs)

    monkeypatch.setattr(fewlabel, "pseudo_labels", spy)
    rows = np.flatnonzero(np.isin(data.split, ["train", "unlabelled"]))
    for rate in (0.0, 1.5):
        cfg = ContactTrainConfig(unlabelled="manifold", context_frames=1, label_recency=rate)
        labels = data.targets.astype(np.float64).copy()
        found = _pseudo_labels(data, labels, ["x_mm", "y_mm", "force_n"], cfg, dataset_windows(data, cfg))
        if rate == 0:
            assert seen["weights"] is None
            continue
        t = data.extra("time_s")[rows]
        expected = recency_weights(t, rate, data.groups[rows])
        np.testing.assert_allclose(seen["weights"], expected)
        first = rows < 100
        assert seen["weights"][first].max() == 1.0 and seen["weights"][~first].max() == 1.0   # each run's last
        assert "later labels weighted" in found["methods"][2] and "weighted" not in found["methods"][0]
    for bad in (-0.5, 11.0, float("nan")):
        with pytest.raises(ConfigError, match="label_recency"):
            ContactTrainConfig(label_recency=bad)


def test_the_manifold_run_has_enough_validation_samples_to_calibrate_sigma(few_label_runs) -> None:
    """The manifold run validates on its pseudo-labelled presses too: enough of them, where "ignore" (warned
    about in the fixture) has 3."""
    from tactile_manip.learning.contact.train import MIN_SIGMA_SAMPLES

    _, manifold, ignore = few_label_runs
    assert ignore["val_samples"] < MIN_SIGMA_SAMPLES <= manifold["val_samples"]


def test_the_train_command_shows_each_labelling_stage_and_the_true_time_of_each_part(labelled_presses, tmp_path,
                                                                                     capsys, monkeypatch) -> None:
    pytest.importorskip("torch", reason="training needs torch")
    import re

    from tactile_manip.cli import main
    from tactile_manip.data import save_dataset
    from tactile_manip.learning.contact import fewlabel

    save_dataset(tmp_path / "few.npz", _hide_labels(labelled_presses(300), 20))
    cfg = tmp_path / "few.toml"
    cfg.write_text('kind = "contact"\ntargets = ["x_mm", "y_mm"]\nhidden = 8\nmembers = 1\nepochs = 2\n'
                   'unlabelled = "manifold"\nthreads = 1\n')
    blas = []
    real = fewlabel.pseudo_labels

    def spy(*args, **kwargs):   # how many threads numpy's BLAS may use while the labeller runs
        threadpoolctl = pytest.importorskip("threadpoolctl")
        blas.extend(p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas")
        return real(*args, **kwargs)

    monkeypatch.setattr(fewlabel, "pseudo_labels", spy)
    assert main(["train", "--config", str(cfg), "--data", str(tmp_path / "few.npz"), "--out", str(tmp_path / "m")]) == 0
    out, err = capsys.readouterr()
    for stage in ("mapping the readings: 3/3 map", "each target's fit by leave-one-out: 2/2 target",
                  "leave-one-out of the field model's refit: ", "placing the unlabelled presses: "):
        assert re.search(f"^labelling: {re.escape(stage)}.* in [0-9.]+ s$", err, re.M), (stage, err)
    # the labelling, the network and the whole command, each its own time: the network's alone is not the command's
    assert re.search(r"labelled from 20 in \d+ s;", out), out
    times = re.search(r"labelling (\d+) s, network (\d+) s, train in all (\d+) s;", out)
    assert times and int(times.group(3)) >= int(times.group(1)) + int(times.group(2)) - 1, out
    assert blas and set(blas) == {1}, blas


def _bent_presses(seed: int, n: int = 900):
    """Readings (N, 15) and force (N,) of presses at one place whose force bends with depth: stiff to 60 % of the
    stroke, then a fifth as stiff (the eFlesh normal run's force against the field norm bends, more softly)."""
    rng = np.random.default_rng(seed)
    depth = rng.uniform(0, 1, n)
    force = np.where(depth < 0.6, 40.0 * depth, 24.0 + 8.0 * (depth - 0.6))
    direction = rng.normal(size=15)
    readings = depth[:, None] * 2000.0 * direction / np.linalg.norm(direction) + rng.normal(0, 2.0, (n, 15))
    return readings, force


def test_the_field_norm_s_line_bends_where_the_force_does() -> None:
    errors = []
    for seed in range(6):
        readings, force = _bent_presses(seed)
        lab = _labelled_mask(len(force), 25, seed=seed)
        found = pseudo_labels(readings, force[:, None], lab)
        assert found.methods[0].startswith("field norm, bent at 2 knots"), found.methods
        errors.append(float(np.sqrt(np.mean((found.values[~lab, 0] - force[~lab]) ** 2))))
    # the bent line: 0.45 N mean over these draws; a cubic of the norm in its place (the fit before): 0.60 N
    assert np.mean(errors) < 0.52, errors


def test_the_norm_s_knots_follow_the_labels_and_the_readings() -> None:
    from tactile_manip.learning.contact.fewlabel import LABELS_PER_KNOT, NORM_KNOTS, norm_knots

    scaled = np.random.default_rng(0).uniform(0, 3, 500)

    def knots(labels):
        return norm_knots(scaled, _labelled_mask(500, labels))

    assert len(knots(5)) == NORM_KNOTS[0]                      # the fewest knots below a dozen labels
    assert len(knots(4 * LABELS_PER_KNOT)) == 4
    assert len(knots(400)) == NORM_KNOTS[1]
    found = knots(100)
    np.testing.assert_allclose(found, np.quantile(scaled, np.arange(1, 9) / 9))  # at the readings' quantiles
    few = norm_knots(np.repeat([0.0, 1.0, 2.0], 100), _labelled_mask(300, 100))
    assert len(few) < NORM_KNOTS[1] and np.all(np.diff(few) > 0)  # readings at three norms: knots that coincide
                                                                  # count once


def test_presses_all_at_one_force_are_labelled_with_it() -> None:
    readings, _ = _bent_presses(1, 400)
    earlier = np.roll(readings, 2, axis=0)
    lab = _labelled_mask(400, 25, seed=1)
    found = pseudo_labels(readings, np.full((400, 1), 12.5), lab, earlier=earlier)
    np.testing.assert_allclose(found.values[:, 0], 12.5, atol=1e-6)
    assert found.loo_rmse[0] < 1e-6


def test_fewer_labels_than_the_norm_fit_s_terms_still_give_finite_nearby_labels() -> None:
    readings, earlier, force = _hysteretic_presses()
    errors = []
    for seed in range(4):  # 5 labels; the fit has 1 + 2 + 2 + 2 terms and an intercept
        lab = _labelled_mask(len(force), MIN_LABELLED, seed=seed)
        found = pseudo_labels(readings, force[:, None], lab, earlier=earlier, names=["force_n"])
        assert np.isfinite(found.values).all() and np.isfinite(found.loo_rmse).all()
        errors.append(float(np.sqrt(np.mean((found.values[~lab, 0] - force[~lab]) ** 2))))
    assert max(errors) < 0.25 * force.std(), errors
