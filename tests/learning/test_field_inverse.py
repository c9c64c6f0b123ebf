"""Placing presses by inverting a smooth model of the field, fitted on a scattered first placing."""

from __future__ import annotations

import functools
import io
import re

import numpy as np
import pytest

from tactile_manip.learning.contact import fewlabel, field_inverse
from tactile_manip.learning.contact.field_inverse import refine_places, settle
from tactile_manip.learning.contact.fewlabel import pseudo_labels, reading_maps
from tactile_manip.progress import progress_bar

CHIPS_MM = np.array([[0.0, 0.0], [-7.0, 0.0], [7.0, 0.0], [0.0, -7.0], [0.0, 7.0]])


def _field(places_mm: np.ndarray, scale: np.ndarray, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """Readings (N, 15) of five chips under a press at ``places_mm`` (N, 2): each chip reads a dipole-like
    vector pointing from the press, its size ``scale`` (N,) (how hard the press is)."""
    rel = places_mm[:, None, :] - CHIPS_MM[None]
    vec = np.concatenate([rel, np.full(rel.shape[:2] + (1,), 6.0)], axis=2)
    field = vec / (np.sum(vec ** 2, axis=2, keepdims=True) ** 1.5) * 1e4 * scale[:, None, None]
    field = field.reshape(len(places_mm), -1)
    return field + np.random.default_rng(seed).normal(0.0, noise, field.shape)


def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


@pytest.fixture(scope="module")
def presses():
    rng = np.random.default_rng(4)
    truth = rng.uniform(-12.0, 12.0, (1500, 2))
    readings = _field(truth, rng.uniform(0.5, 2.0, 1500), noise=0.05)
    labelled = np.zeros(1500, bool)
    labelled[rng.choice(1500, 25, replace=False)] = True
    return readings, truth, labelled


def test_a_scattered_placing_is_pulled_onto_the_field(presses) -> None:
    readings, truth, labelled = presses
    scattered = truth + np.random.default_rng(1).normal(0.0, 1.0, truth.shape) * ~labelled[:, None]
    refined = refine_places(readings, scattered, labelled)
    before, after = _rmse(scattered[~labelled], truth[~labelled]), _rmse(refined[~labelled], truth[~labelled])
    assert after < 0.5 * before, (before, after)
    np.testing.assert_array_equal(refined[labelled], scattered[labelled])  # labelled presses stay
    # float32 readings place the presses where float64 ones do (to the grid's step)
    single = refine_places(readings.astype(np.float32), scattered, labelled)
    step = 24.0 * 1.12 / 120
    assert np.mean(np.abs(single - refined) <= step + 1e-9) > 0.99


def test_the_finer_second_pass_places_closer_than_the_first_alone_or_repeated(presses, monkeypatch) -> None:
    readings, truth, labelled = presses
    scattered = truth + np.random.default_rng(1).normal(0.0, 2.0, truth.shape) * ~labelled[:, None]

    def error(passes) -> float:
        monkeypatch.setattr(field_inverse, "PASSES", passes)
        return _rmse(refine_places(readings, scattered, labelled)[~labelled], truth[~labelled])
    passes = field_inverse.PASSES
    first, repeated, finer = error(passes[:1]), error(passes[:1] * 2), error(passes[:2])
    assert finer < 0.95 * min(first, repeated), (first, repeated, finer)  # 1.40, 1.24, 1.15 mm


@pytest.mark.parametrize("case", ["smooth", "patterned"])
def test_the_coarse_then_fine_grid_search_places_every_press_where_the_whole_grid_does(presses, case,
                                                                                      monkeypatch) -> None:
    readings, truth, labelled = presses if case == "smooth" else _patterned(8.0)
    scattered = truth + np.random.default_rng(1).normal(0.0, 2.0, truth.shape) * ~labelled[:, None]
    shipped = refine_places(readings, scattered, labelled)
    monkeypatch.setattr(field_inverse, "COARSE", 1)  # every grid point scored
    np.testing.assert_array_equal(shipped, refine_places(readings, scattered, labelled))


def test_where_the_rig_puts_its_origin_changes_nothing_but_the_places_offset(presses) -> None:
    readings, truth, labelled = presses
    scattered = truth + np.random.default_rng(1).normal(0.0, 2.0, truth.shape) * ~labelled[:, None]
    plain = refine_places(readings, scattered, labelled)
    for offset in ([300.0, -300.0], [3000.0, 40.0]):  # a stage's frame far from the pad's centre
        moved = refine_places(readings, scattered + offset, labelled) - offset
        assert np.mean(np.abs(moved - plain) < 1e-6) > 0.99, offset


def test_only_the_rows_asked_for_move(presses) -> None:
    readings, truth, labelled = presses
    scattered = truth + np.random.default_rng(2).normal(0.0, 1.0, truth.shape)
    rows = np.array([3, 10])
    moved = refine_places(readings, scattered, labelled, rows=rows)
    keep = np.ones(len(truth), bool)
    keep[rows] = False
    np.testing.assert_array_equal(moved[keep], scattered[keep])
    assert np.all(moved[rows] != scattered[rows])


def test_rows_left_out_of_the_fit_are_placed_on_models_that_never_saw_them(presses) -> None:
    # a run's test presses are placed on the models of its training presses, which they do not move
    readings, truth, labelled = presses
    scattered = truth + np.random.default_rng(1).normal(0.0, 1.0, truth.shape) * ~labelled[:, None]
    unseen = np.zeros(len(truth), bool)
    unseen[-300:] = True
    seen = field_inverse.places_by_pass(readings[~unseen], scattered[~unseen], labelled[~unseen])
    both = field_inverse.places_by_pass(readings, scattered, labelled, fitted=~unseen)
    np.testing.assert_array_equal(both[:, ~unseen], seen)  # the fitted rows as if the others were not there
    free = unseen & ~labelled
    assert _rmse(both[-1][free], truth[free]) < 0.5 * _rmse(scattered[free], truth[free])
    # where the unseen rows start changes nothing: the models are the fitted rows', the search the whole pad's
    wild = scattered.copy()
    wild[free] = np.random.default_rng(5).uniform(-12.0, 12.0, (free.sum(), 2))
    np.testing.assert_array_equal(field_inverse.places_by_pass(readings, wild, labelled, fitted=~unseen), both)
    with pytest.raises(ValueError, match="fitted-rows mask of shape"):
        field_inverse.places_by_pass(readings, scattered, labelled, fitted=~unseen[:10])


def test_presses_of_one_depth_per_place_are_placed_by_the_direction_alone(presses, monkeypatch) -> None:
    _, truth, labelled = presses
    readings = _field(truth, 1.0 + truth[:, 0] / 24.0, noise=0.05)   # the place sets how hard the press is
    scattered = truth + np.random.default_rng(3).normal(0.0, 1.0, truth.shape) * ~labelled[:, None]
    before = _rmse(scattered[~labelled], truth[~labelled])
    alone = _rmse(refine_places(readings, scattered, labelled)[~labelled], truth[~labelled])
    monkeypatch.setattr(field_inverse, "LEVEL_EXPLAINED", 1.1)   # keep the norm in the model all the same
    with_norm = _rmse(refine_places(readings, scattered, labelled)[~labelled], truth[~labelled])
    assert alone < 0.45 * before and alone < with_norm, (before, alone, with_norm)


def test_places_along_a_line_are_refined_too() -> None:
    rng = np.random.default_rng(5)
    along = rng.uniform(-12.0, 12.0, 800)
    truth = np.stack([along, np.full(800, 2.0)], axis=1)
    readings = _field(truth, rng.uniform(0.5, 2.0, 800), noise=0.05)
    labelled = np.zeros(800, bool)
    labelled[:10] = True
    first = along + rng.normal(0.0, 1.0, 800) * ~labelled
    refined = refine_places(readings, first[:, None], labelled)[:, 0]
    assert np.sqrt(np.mean((refined - along)[~labelled] ** 2)) < 0.5 * np.sqrt(np.mean((first - along)[~labelled] ** 2))


def test_readings_too_few_for_the_finer_models_leave_those_passes_out(presses, monkeypatch) -> None:
    readings, truth, labelled = (part[:600] for part in presses)  # the last pass's model has 258 terms
    scattered = truth + np.random.default_rng(1).normal(0.0, 1.0, truth.shape) * ~labelled[:, None]
    shipped = refine_places(readings, scattered, labelled)
    assert _rmse(shipped[~labelled], truth[~labelled]) < 0.5 * _rmse(scattered[~labelled], truth[~labelled])
    monkeypatch.setattr(field_inverse, "PASSES", field_inverse.PASSES[:5])  # 600 rows: 150 terms at most
    np.testing.assert_array_equal(shipped, refine_places(readings, scattered, labelled))
    monkeypatch.setattr(field_inverse, "PASSES", field_inverse.PASSES[:4])
    assert not np.array_equal(shipped, refine_places(readings, scattered, labelled))


def test_too_few_readings_or_places_that_do_not_spread_are_returned_as_they_are(presses) -> None:
    readings, truth, labelled = presses
    few = refine_places(readings[:100], truth[:100] + 1.0, labelled[:100])   # 100 rows, 45 terms
    np.testing.assert_array_equal(few, truth[:100] + 1.0)
    for still in (np.zeros_like(truth), np.tile([300.0, -100.0], (len(truth), 1))):  # at the origin or off it
        np.testing.assert_array_equal(refine_places(readings, still, labelled), still)
    everyone = np.ones(len(truth), bool)
    np.testing.assert_array_equal(refine_places(readings, truth, everyone), truth)
    with pytest.raises(ValueError, match="3 coordinates"):
        refine_places(readings, np.hstack([truth, truth[:, :1]]), labelled)


@pytest.mark.slow  # about 25 s: the refit's leave-one-out over 25 held-out presses
def test_the_labeller_refines_named_places_and_scores_the_refit_by_leave_one_out(presses) -> None:
    readings, truth, labelled = presses
    names = ["x_mm", "y_mm"]
    maps = reading_maps(readings)  # shared by the calls below
    mapped = pseudo_labels(readings, truth, labelled, names=names, refine=False, maps=maps)
    refined = pseudo_labels(readings, truth, labelled, names=names, maps=maps)
    assert all("refined on the field model in " in m and "(mean of" in m for m in refined.methods)
    assert not any("refined" in m for m in mapped.methods)
    before = _rmse(mapped.values[~labelled], truth[~labelled])
    after = _rmse(refined.values[~labelled], truth[~labelled])
    assert after < before, (before, after)
    np.testing.assert_array_equal(refined.values[labelled], truth[labelled])
    assert refined.loo_rmse.shape == (2,) and np.all(np.isfinite(refined.loo_rmse)) and np.all(refined.loo_rmse > 0)
    # the refit's leave-one-out says about how far its places are off, per coordinate
    per_axis = np.sqrt(np.mean((refined.values[~labelled] - truth[~labelled]) ** 2, axis=0))
    assert np.all(refined.loo_rmse < 4 * per_axis), (refined.loo_rmse, per_axis)
    assert np.all(refined.loo_rmse > per_axis / 4), (refined.loo_rmse, per_axis)
    # without names nothing is a place, and nothing is refined
    assert not any("refined" in m for m in pseudo_labels(readings, truth, labelled, maps=maps).methods)
    # on this smooth field the finer passes learn the placing's errors; the labels' leave-one-out sees it, and the
    # labeller keeps the places after fewer passes (1 here: 0.56 mm, where all six leave 0.61 mm)
    count = int(re.search(r"in (\d+) pass", refined.methods[0]).group(1))
    score = lambda fit, k: fewlabel._loo_rmse(fit, truth[:, k], labelled)  # noqa: E731
    every = fewlabel._refit(readings, truth, labelled, fewlabel._starts(fewlabel._fits_by_map(maps), [0, 1], score))
    assert every.shape == (len(field_inverse.PASSES), *truth.shape)
    np.testing.assert_array_equal(refined.values[~labelled], every[count - 1][~labelled])
    errors = [_rmse(places[~labelled], truth[~labelled]) for places in every]
    assert count < len(field_inverse.PASSES) and errors[count - 1] < 0.97 * errors[-1], (count, errors)


def test_exact_labels_pull_a_stretched_placing_back_the_more_of_them_there_are(presses) -> None:
    readings, truth, _ = presses
    errors = []
    for count in (25, 300):
        labelled = np.zeros(len(truth), bool)
        labelled[np.random.default_rng(count).choice(len(truth), count, replace=False)] = True
        stretched = np.where(labelled[:, None], truth, 1.1 * truth + 0.02 * truth ** 2 / 12.0)  # a broad warp
        refined = refine_places(readings, stretched, labelled)
        errors.append((_rmse(stretched[~labelled], truth[~labelled]), _rmse(refined[~labelled], truth[~labelled])))
    (before_few, after_few), (before_many, after_many) = errors
    assert after_few < 0.9 * before_few and after_many < 0.7 * before_many and after_many < after_few, errors


def _patterned(period_mm: float, half_width_mm: float = 12.0):
    """Presses of a smooth field (chips 15 mm below the pad) with a pattern repeating every ``period_mm`` across
    the pad, as a printed lattice of cells makes, 3 % of the field's size; 25 of 1500 labelled."""
    rng = np.random.default_rng(4)
    truth = rng.uniform(-half_width_mm, half_width_mm, (1500, 2))
    rel = truth[:, None, :] - CHIPS_MM[None]
    vec = np.concatenate([rel, np.full(rel.shape[:2] + (1,), 15.0)], axis=2)
    smooth = (vec / np.sum(vec ** 2, axis=2, keepdims=True) ** 1.5 * rng.uniform(0.5, 2.0, 1500)[:, None, None])
    smooth = smooth.reshape(len(truth), -1)
    size = np.linalg.norm(smooth, axis=1)[:, None]
    pattern = np.random.default_rng(7).normal(size=(2, smooth.shape[1]))
    pattern /= np.linalg.norm(pattern, axis=1, keepdims=True)
    phase = 2.0 * np.pi * truth / period_mm
    readings = smooth + 0.03 * size * (np.cos(phase[:, :1]) * pattern[0] + np.sin(phase[:, 1:]) * pattern[1])
    readings += np.random.default_rng(0).normal(0.0, 0.003 * float(size.mean()), readings.shape)
    labelled = np.zeros(len(truth), bool)
    labelled[rng.choice(len(truth), 25, replace=False)] = True
    return readings, truth, labelled


def test_the_last_pass_finds_the_pattern_that_repeats_with_the_cells_and_places_closer(monkeypatch) -> None:
    readings, truth, labelled = _patterned(8.0)
    direction = readings / np.linalg.norm(readings, axis=1, keepdims=True)
    assert field_inverse._lattice_period(direction, truth, np.ones((len(truth), 1)), 5) == 8.0
    scattered = truth + np.random.default_rng(1).normal(0.0, 2.0, truth.shape) * ~labelled[:, None]
    passes = field_inverse.PASSES
    assert [lattice for *_, lattice in passes] == [False, False, True, True, True, True]

    def error(chosen) -> float:
        monkeypatch.setattr(field_inverse, "PASSES", chosen)
        return _rmse(refine_places(readings, scattered, labelled)[~labelled], truth[~labelled])
    two, three = error(passes[:2]), error(passes[:3])
    assert three < 0.95 * two, (two, three)  # 0.82, 0.72 mm


def test_a_pad_too_small_for_the_pattern_to_repeat_skips_the_last_pass(monkeypatch) -> None:
    readings, truth, labelled = _patterned(8.0, half_width_mm=4.0)  # 8 mm across: no period fits twice
    direction = readings / np.linalg.norm(readings, axis=1, keepdims=True)
    assert field_inverse._lattice_period(direction, truth, np.ones((len(truth), 1)), 5) is None
    scattered = truth + np.random.default_rng(1).normal(0.0, 0.5, truth.shape) * ~labelled[:, None]
    shipped = refine_places(readings, scattered, labelled)
    monkeypatch.setattr(field_inverse, "PASSES", field_inverse.PASSES[:2])
    np.testing.assert_array_equal(shipped, refine_places(readings, scattered, labelled))


@pytest.mark.slow  # about 14 s: three labellings with their refits
def test_refits_started_from_maps_bent_opposite_ways_average_their_bends_out(presses, monkeypatch) -> None:
    readings, truth, _ = (part[:800] for part in presses)
    labelled = np.zeros(len(truth), bool)
    labelled[np.random.default_rng(5).choice(len(truth), 25, replace=False)] = True
    names = ["x_mm", "y_mm"]
    monkeypatch.setattr(fewlabel, "REFINED_LOO", 4)  # the leave-one-out is tested above; here it only costs time

    def bent(sign: float, seed: int) -> np.ndarray:  # a map of the presses, bent across the pad and scattered
        warp = sign * 3.0 * np.sin(truth[:, ::-1] / 5.0)
        scatter = np.random.default_rng(seed).normal(0.0, 0.5, (len(truth), 3))
        return np.hstack([truth + warp, np.zeros((len(truth), 1))]) + scatter
    maps = {"one way": bent(1.0, 0), "the other": bent(-1.0, 1)}
    alone = [pseudo_labels(readings, truth, labelled, names=names, maps={name: m}) for name, m in maps.items()]
    both = pseudo_labels(readings, truth, labelled, names=names, maps=maps)
    assert all("(mean of 2 starts)" in m for one in alone for m in one.methods)
    assert all("(mean of 4 starts)" in m for m in both.methods)
    errors = [_rmse(found.values[~labelled], truth[~labelled]) for found in (*alone, both)]
    assert errors[2] < 0.7 * min(errors[:2]), errors
    # a map whose fits are far worse than the best map's starts no refit: the places are those without it
    wrong = np.random.default_rng(2).normal(0.0, 10.0, (len(truth), 3))
    with_wrong = pseudo_labels(readings, truth, labelled, names=names, maps={**maps, "wrong": wrong})
    np.testing.assert_array_equal(with_wrong.values, both.values)
    assert with_wrong.methods == both.methods


def test_settling_takes_out_a_bend_that_the_passes_keep() -> None:
    readings, truth, labelled = _patterned(8.0)
    free = ~labelled
    bent = np.where(labelled[:, None], truth, truth + 2.0 * np.sin(truth[:, ::-1] / 5.0))  # pinned at the labels
    passed = field_inverse.places_by_pass(readings, bent, labelled)[-1]
    settled = settle(readings, passed, labelled)
    assert _rmse(settled[free], truth[free]) < 0.85 * _rmse(passed[free], truth[free])  # 1.20 to 0.97 mm
    np.testing.assert_array_equal(settled[labelled], truth[labelled])  # labelled presses stay
    np.testing.assert_array_equal(settled, settle(readings, passed, labelled))  # the seed fixes the shaking
    other = settle(readings, passed, labelled, seed=1)
    assert not np.array_equal(other, settled)
    assert abs(_rmse(other[free], truth[free]) - _rmse(settled[free], truth[free])) < 0.1
    rows = np.flatnonzero(free)[:40]  # only the rows asked for move
    some = settle(readings, passed, labelled, rows=rows)
    still = np.ones(len(truth), bool)
    still[rows] = False
    np.testing.assert_array_equal(some[still], passed[still])
    assert not np.array_equal(some[rows], passed[rows])


def test_settling_places_it_cannot_model_returns_them_as_they_are(presses) -> None:
    readings, truth, labelled = presses
    few = settle(readings[:100], truth[:100] + 1.0, labelled[:100])  # too few rows for the finer models
    np.testing.assert_array_equal(few, truth[:100] + 1.0)
    still = np.tile([300.0, -100.0], (len(truth), 1))
    np.testing.assert_array_equal(settle(readings, still, labelled), still)
    np.testing.assert_array_equal(settle(readings, truth, np.ones(len(truth), bool)), truth)
    small = _patterned(8.0, half_width_mm=4.0)  # no period fits twice: no repeating terms to settle with
    np.testing.assert_array_equal(settle(small[0], small[1], small[2]), small[1])
    with pytest.raises(ValueError, match="3 coordinates"):
        settle(readings, np.hstack([truth, truth[:, :1]]), labelled)


def test_the_labeller_settles_the_places_where_a_pass_that_settling_repeats_holds_out_best(presses,
                                                                                           monkeypatch) -> None:
    readings, truth, labelled = (part[:800] for part in presses)
    names = ["x_mm", "y_mm"]
    maps = reading_maps(readings)
    score = lambda fit, k: fewlabel._loo_rmse(fit, truth[:, k], labelled)  # noqa: E731
    starts = fewlabel._starts(fewlabel._fits_by_map(maps), [0, 1], score)
    passes = len(field_inverse.PASSES)
    first_repeated = passes - len(field_inverse.SETTLE_PASSES) + 1   # the first pass that settling repeats
    for best in range(1, passes + 1):
        loo = np.tile(np.abs(np.arange(1.0, passes + 1) - best)[:, None] + 1.0, (1, 2))  # least after `best`
        monkeypatch.setattr(fewlabel, "_refined_errors", lambda *args, loo=loo, **kwargs: loo[None])  # one held out
        found = pseudo_labels(readings, truth, labelled, names=names, maps=maps)
        np.testing.assert_array_equal(found.loo_rmse, loo[best - 1])  # the passes' own leave-one-out
        if best >= first_repeated:
            assert all(f", refined on the field model in {passes} passes, settled (leave-one-out least after {best})"
                       f" (mean of" in m for m in found.methods), found.methods
            if best in (first_repeated, passes):   # settling is the costly part: checked at the two ends
                np.testing.assert_array_equal(
                    found.values, fewlabel._refit(readings, truth, labelled, starts, settled=True))
        else:
            assert not any("settled" in m for m in found.methods)
            if best == 1:
                np.testing.assert_array_equal(found.values, fewlabel._refit(readings, truth, labelled, starts)[0])



@pytest.mark.slow  # about 10 s: the labeller in full, once shown and once not
def test_the_labeller_reports_each_stage_as_it_goes_and_labels_as_it_does_unseen(presses) -> None:
    readings, truth, labelled = (part[:600] for part in presses)
    names = ["x_mm", "y_mm"]
    log = io.StringIO()
    shown = pseudo_labels(readings, truth, labelled, names=names,
                          stages=functools.partial(progress_bar, stream=log, heartbeat_s=0.0))
    lines = log.getvalue().splitlines()
    ends = [line for line in lines if re.search(r" in [0-9.]+ s$", line)]
    assert [line.split(": ")[1] for line in ends] == [
        "mapping the readings", "each target's fit by leave-one-out", "leave-one-out of the field model's refit",
        "placing the unlabelled presses"], lines
    starts = int(re.search(r"mean of (\d+) starts", shown.methods[0]).group(1))
    refits = labelled.sum() * starts   # every labelled press held out, from every start
    assert ends[2].startswith(f"labelling: leave-one-out of the field model's refit: {refits}/{refits} refit in ")
    # the longest stage says where it is after every refit (here the heartbeat is 0 s)
    assert sum(line.endswith(" s so far") and "refit" in line for line in lines) == refits
    assert ends[3].startswith(f"labelling: placing the unlabelled presses: {starts}/{starts} start in ")
    unseen = pseudo_labels(readings, truth, labelled, names=names)
    np.testing.assert_array_equal(shown.values, unseen.values)
    np.testing.assert_array_equal(shown.loo_rmse, unseen.loo_rmse)


@pytest.mark.slow
def test_on_the_real_cube_the_finer_passes_place_closer_than_the_first_three(eflesh_dir, tmp_path,
                                                                             monkeypatch) -> None:
    """The eFlesh spatial run's training presses, 25 of them labelled, placed first by the affine fit of the map
    of the readings' direction: the passes after the third follow the field's finer detail (1.75 to 1.64 mm), and
    settling takes out much of the bend left between the labels."""
    from tactile_manip.cli import main
    from tactile_manip.data.io import load_dataset

    run = eflesh_dir / "spatial_20250316_155729"
    out = tmp_path / "spatial.npz"
    assert main(["import", "--readings-csv", str(run / "sensor_post_baselines.csv"), "--labels-csv",
                 str(run / "states.csv"), "--label-columns", "time_s,x_mm,y_mm,z_mm", "--contact", "z_mm < 145.1",
                 "--targets", "x_mm,y_mm", "--board", "eflesh", "--out", str(out)]) == 0
    data = load_dataset(out)
    train = np.asarray(data.split) == "train"
    readings = data.readings[train].reshape(int(train.sum()), -1).astype(np.float64)
    readings = readings[:, readings.std(axis=0) > 0]
    truth = np.stack([data.target("x_mm"), data.target("y_mm")], axis=1)[train].astype(np.float64)
    labelled = np.zeros(len(truth), bool)
    labelled[np.random.default_rng(0).choice(len(truth), 25, replace=False)] = True
    coords = reading_maps(readings)["direction"][:, :2]
    first = np.stack([fewlabel._affine(coords / coords.std())(labelled, truth[:, k]) for k in range(2)], axis=1)
    first[labelled] = truth[labelled]
    errors, passes = [], field_inverse.PASSES
    for count in (3, len(passes)):
        monkeypatch.setattr(field_inverse, "PASSES", passes[:count])
        placed = refine_places(readings, first, labelled)
        errors.append(_rmse(placed[~labelled], truth[~labelled]))
    assert errors[1] < 0.96 * errors[0], errors
    # settling then takes out much of the bend the passes keep between the labels
    settled = _rmse(settle(readings, placed, labelled)[~labelled], truth[~labelled])
    assert settled < 0.92 * errors[1], (errors, settled)
