"""The force-limit benchmark's pieces on a synthetic press log (no eFlesh run here): its draws, its features taken
from the first 80 % only, its diagnosis, limits and report."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("sklearn")

from benchmarks.force_limit import (breakdown, features, labelled_rows, markdown, plot, section_diagnosis,  # noqa: E402
                                    section_limits)


def _run(cycles: int = 12, per_cycle: int = 80, seed: int = 0) -> dict:
    """A probe pressing one place in and out: the stage z, a force that softens over the run and is lower on the
    way in, readings along one field direction growing with depth, and the chronological 80/20 split."""
    rng = np.random.default_rng(seed)
    n = cycles * per_cycle
    t = np.arange(n) * 0.07
    phase = np.arange(n) / per_cycle % 1.0
    depth = 1.0 - np.abs(2.0 * phase - 1.0)
    force = (30.0 * depth ** 1.3 - np.where(phase < 0.5, 1.0, -1.0) * 3.0 * depth * (1 - depth)) * (1 - 0.03 * t / t[-1])
    direction = rng.normal(size=15)
    x = depth[:, None] * 2000.0 * direction / np.linalg.norm(direction) + rng.normal(0, 2.0, (n, 15))
    shifted = [x[np.maximum(np.arange(n) - k, 0)] for k in (1, 2)]
    cut = int(0.8 * n)
    return {"x": x, "middle": shifted[0], "earlier": shifted[1], "t": t, "force": force, "z": 288.0 - 12.0 * depth,
            "train": np.arange(cut), "test": np.arange(cut, n)}


def test_the_labelled_rows_are_import_s_draw_from_the_first_80_percent() -> None:
    d = _run()
    lab = labelled_rows(d, 25, seed=0)
    assert lab.sum() == 25 and lab[d["train"]].sum() == 25
    assert not np.array_equal(lab, labelled_rows(d, 25, seed=1))
    np.testing.assert_array_equal(lab, labelled_rows(d, 25, seed=0))


def test_the_features_take_their_statistics_from_the_first_80_percent_alone() -> None:
    d = _run()
    before = features(d)
    d["x"][d["test"]] *= 3.0                    # the test tail's readings change; nothing fitted may move
    after = features(d)
    for key in ("norm", "axes", "elapsed"):
        np.testing.assert_allclose(after[key][d["train"]], before[key][d["train"]])
    assert before["elapsed"][d["train"]].max() == pytest.approx(1.0)


def test_the_diagnosis_limits_and_report_of_a_synthetic_run(tmp_path) -> None:
    d = _run()
    feat = features(d)
    diag = section_diagnosis(d, feat, 25, draws=3)
    bent = diag["bent line"]
    assert bent["draws"] == 3 and len(bent["per_draw"]) == 3
    assert bent["every_label"]["rmse"] < bent["mean"]                     # more labels, closer
    assert set(bent["seed_0"]["phases"]) == {"pressing in", "springing back", "holding"}
    limits = section_limits(d, feat, 25, draws=3)
    # knowing the all-label shape leaves only a gain and an offset to the labels
    assert limits["known_shape_gain_offset_from_k"]["mean"] < bent["mean"]
    report = {"run": "synthetic", "k": 25, "diagnosis": diag, "limits": limits}
    text = markdown(report)
    assert "bent line" in text and "kernel ridge" in text
    plot(d, feat, 25, tmp_path / "limit.png")
    assert (tmp_path / "limit.png").stat().st_size > 0


def test_a_perfect_prediction_breaks_down_to_zero_everywhere() -> None:
    d = _run()
    out = breakdown(d["force"].copy(), d)
    assert out["rmse"] == 0.0 and all(q == 0.0 for q in out["quarters"])
    assert all(row["rmse"] == 0.0 for row in out["phases"].values() if row["rows"])
