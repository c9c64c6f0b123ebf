"""The few-label map benchmark's measurements, on readings whose map is known."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.fewlabel_map import grid_rows, main, markdown, measure


def _pad(bend: float) -> tuple[np.ndarray, np.ndarray]:
    """A 14 x 14 grid of presses, 1 mm apart, read by 6 channels: linear in the place, plus ``bend`` times a
    fold that no affine map of the place undoes."""
    g = np.arange(14, dtype=float)
    pos = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    rng = np.random.default_rng(0)
    lin = np.hstack([pos, np.ones((len(pos), 1))]) @ rng.normal(size=(3, 6)) + 5.0
    fold = np.sin(pos[:, :1] / 2.5) * rng.normal(size=(1, 6)) * 4.0
    return lin + bend * fold, pos


@pytest.mark.slow  # about 30 s: two maps of 1500 presses and the labeller on each
def test_a_flat_map_is_fitted_by_an_affine_map_and_a_folded_one_is_not() -> None:
    flat, pos = _pad(0.0)
    folded, _ = _pad(1.0)
    a = measure(flat, pos, k=25, seeds=[0])
    b = measure(folded, pos, k=25, seeds=[0])
    assert a["map_every_label"]["reading"]["affine_2_mm"] < 0.1
    assert b["map_every_label"]["reading"]["affine_2_mm"] > 5 * a["map_every_label"]["reading"]["affine_2_mm"]
    # the refit's field model, fitted at the true places, places a flat pad's presses to within a grid step or so
    assert a["map_every_label"]["field model"]["inverted_mm"] < 0.3
    # a linear pad is labelled almost exactly from 25 labels; the fold costs the labeller
    assert a["random"]["mean"]["all_mm"] < 0.2
    assert b["random"]["mean"]["all_mm"] > a["random"]["mean"]["all_mm"]


def test_the_labellers_error_is_split_into_inside_and_outside_the_labelled_hull() -> None:
    readings, pos = _pad(1.0)
    out = measure(readings, pos, k=9, seeds=[1, 2])
    for row in [*out["random"]["per_seed"].values(), out["grid"], *out["random_map_only"]["per_seed"].values(),
                out["grid_map_only"]]:
        share = row["inside_share"]
        assert 0.0 < share <= 1.0
        whole = np.sqrt(share * row["inside_mm"] ** 2 + (1 - share) * np.nan_to_num(row["outside_mm"]) ** 2)
        assert whole == pytest.approx(row["all_mm"], rel=1e-9)
        # so are the bands of distance to the nearest labelled press
        bands = row["by_nearest_label"]
        assert sum(b["share"] for b in bands) == pytest.approx(1.0)
        assert np.sqrt(sum(b["share"] * np.nan_to_num(b["rmse_mm"]) ** 2 for b in bands)) == pytest.approx(
            row["all_mm"], rel=1e-9)
    # a grid that reaches the corners leaves nothing outside its hull
    assert out["grid"]["inside_share"] == 1.0 and np.isnan(out["grid"]["outside_mm"])
    text = markdown({"run": "synthetic", **out})
    assert "| 9 on a grid | map fits alone |" in text and "| reading |" in text
    assert "| 9 on a grid | map fits, refined on the field model |" in text
    assert "| < 1.5 |" in text and "| 1.5-3 |" in text and "| >= 4.5 |" in text


def test_the_grid_rows_are_distinct_presses_nearest_each_mark() -> None:
    _, pos = _pad(0.0)
    rows = grid_rows(np.vstack([pos, pos]), 25)  # every place pressed twice: one press per mark all the same
    assert len(set(rows.tolist())) == 25
    assert {tuple(p) for p in np.vstack([pos, pos])[rows]} >= {(0.0, 0.0), (13.0, 13.0), (0.0, 13.0), (13.0, 0.0)}


def test_fewer_than_five_labels_are_refused_by_the_command_line(capsys) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["--runs", "nowhere", "--k", "3"])
    assert stop.value.code == 2 and "at least 5" in capsys.readouterr().err
