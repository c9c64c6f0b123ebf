"""The twin protocol's pieces on synthetic logs (no training and no eFlesh run here): explained variance, the
smooth maps that set its limit, the frame fitted for zero labels, and the report."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.twin_limits import (choose_map, explained_variance, forward_limit, inverted_places, map_bank,
                                    pose_grid)
from benchmarks.twin_protocol import TURNS, markdown, plot, score


def _log(n=900, seed=0):
    """A probe log: a grid of places pressed to several depths, readings a smooth field of the pose plus noise."""
    rng = np.random.default_rng(seed)
    pose = np.c_[rng.integers(0, 11, (n, 2)).astype(float), rng.choice([141.0, 142.0, 143.0, 144.0], n)]
    depth = 145.0 - pose[:, 2]
    field = np.stack([np.sin(pose[:, 0] / 3) * depth, np.cos(pose[:, 1] / 4) * depth, depth ** 1.5,
                      (pose[:, 0] - pose[:, 1]) * depth / 5], axis=1) * 50
    return pose, field + rng.normal(0, 2.0, field.shape)


def test_explained_variance_is_one_for_the_truth_zero_for_its_mean_and_counts_a_bias() -> None:
    y = np.random.default_rng(0).normal(size=(200, 3)) * [1.0, 10.0, 100.0]
    per, overall = explained_variance(y, y)
    assert overall == pytest.approx(1.0) and np.allclose(per, 1.0)
    per, overall = explained_variance(np.broadcast_to(y.mean(0), y.shape), y)
    assert overall == pytest.approx(0.0, abs=1e-12)
    per, _ = explained_variance(y + y.std(0), y)  # a bias of one spread costs all the variance
    assert np.allclose(per, 0.0, atol=1e-9)
    # overall weighs each channel by its variance: the third channel's miss dominates
    bad = y.copy()
    bad[:, 2] = y[:, 2].mean()
    assert explained_variance(bad, y)[1] < 0.02


def test_a_smooth_map_of_the_pose_explains_a_smooth_field_and_its_choice_sees_no_test_row() -> None:
    pose, y = _log()
    train, test = np.arange(720), np.arange(720, 900)
    out = forward_limit(pose, y, train, test)
    assert out["best"] in out["maps"] and out["test_ev"] > 0.95
    for row in out["maps"].values():
        assert row["cv_ev"] > 0.9 and len(row["test_ev_per_channel"]) == 4
    # the test rows cannot move the choice: scrambling them leaves the hyper-parameters as they were
    scrambled = y.copy()
    scrambled[test] = np.random.default_rng(1).normal(size=(len(test), 4))
    again = forward_limit(pose, scrambled, train, test)
    assert {n: r["params"] for n, r in again["maps"].items()} == {n: r["params"] for n, r in out["maps"].items()}
    assert again["test_ev"] < 0.1


def test_a_map_read_backwards_places_its_own_presses_and_makes_a_bank() -> None:
    from tactile_manip.data import from_arrays

    pose, y = _log(1500)
    fit = choose_map("thin-plate RBF", pose, y)
    grid = pose_grid(pose, step_mm=0.5, depths=4)
    placed = inverted_places(fit, grid, y[:200])
    assert np.sqrt(np.mean(np.sum((placed[:, :2] - pose[:200, :2]) ** 2, axis=1))) < 0.7
    template = from_arrays(np.zeros((3, 2, 2, 1), np.float32), targets={"x_mm": np.zeros(3)},
                           provenance={"layout": "grid-2x2"})
    bank = map_bank(fit, grid, np.ones(4, bool), template, targets={"x_mm": lambda p: p[:, 0]})
    assert bank.readings.shape == (len(grid), 2, 2, 1) and list(bank.target_names) == ["x_mm"]
    np.testing.assert_allclose(bank.readings.reshape(len(grid), -1), fit.predict(grid), rtol=1e-5, atol=1e-3)


def test_the_zero_label_score_fits_an_offset_and_a_quarter_turn_and_nothing_more() -> None:
    rng = np.random.default_rng(0)
    true = rng.uniform(-10, 10, (300, 2))
    names = ["x_mm", "y_mm"]
    turned = (true @ TURNS[1].T) + [30.0, -4.0]  # the pad frame: turned a quarter and shifted
    assert score(turned, true, names, fit_frame=True) == pytest.approx(0.0, abs=1e-9)
    assert score(turned, true, names) > 20
    assert score(1.5 * true, true, names, fit_frame=True) > 2  # a scale is not fitted
    assert score(np.c_[true[:, :1] + 0.3], true[:, :1], ["force_n"]) == pytest.approx(0.3)


def _report():
    contact = {kind: {"run": f"{kind}_1", "figure": fig, "k": {
        "0": {"mean": {"twin": 3.0}}, "25": {"mean": {"twin": 0.9, "kNN": 6.0, "manifold (committed)": 1.1}},
        "100": {"mean": {"twin": 0.5, "kNN": 3.6, "manifold (committed)": 0.8}}}}
        for kind, fig in (("spatial", "position_rmse_mm"), ("normal", "force_rmse_n"))}
    limit = {"spatial/sensor": {"pose": {"best": "kNN", "test_ev": 0.92}, "pose_and_time": {"best": "kNN",
                                                                                             "test_ev": 0.97}},
             "zero_label_bound": {"test_presses": 961, "position_rmse_mm": 0.5}}
    return {"limit": limit, "forward": {"note": "no simulate-log"}, "contact": contact}


def test_the_report_prints_every_section_and_plots_error_against_k(tmp_path) -> None:
    text = markdown(_report())
    assert "| spatial/sensor | kNN | 0.920 | 0.970 | kNN |" in text
    assert "0.50 mm RMSE off" in text and "no simulate-log" in text
    assert "| 25 | 0.900 | 1.100 | 6.000 |" in text and "| 0 | 3.000 | - | - |" in text
    plot(_report(), tmp_path / "k.png")
    assert (tmp_path / "k.png").stat().st_size > 1000
