"""Confidence calibration: isotonic fit recovers a known success curve, is monotone, and round-trips."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from tactile_manip.extras import MissingExtraError
from tactile_manip.perception.confidence import ConfidenceCalibration, reliability_figure, reliability_table

NEEDS_SKLEARN = "fitting a calibration needs scikit-learn (extra 'sklearn')"


def _synthetic(n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Raw confidence uniform in [0, 1]; P(error <= 5 deg | raw) = raw**2 (an over-confident raw score)."""
    raw = rng.uniform(0, 1, n)
    ok = rng.uniform(0, 1, n) < raw**2
    errors = np.where(ok, rng.uniform(0, 5, n), rng.uniform(5.01, 90, n))
    return raw, errors


def test_fit_recovers_the_success_curve_and_is_monotone():
    pytest.importorskip("sklearn", reason=NEEDS_SKLEARN)
    raw, errors = _synthetic(20000, np.random.default_rng(0))
    cal = ConfidenceCalibration.fit(raw, errors, tolerance_deg=5.0)
    grid = np.linspace(0.05, 0.95, 19)
    np.testing.assert_allclose(cal(grid), grid**2, atol=0.05)
    assert np.all(np.diff(cal.values) >= 0) and np.all(np.diff(cal.knots) > 0)
    assert cal(-1.0) == cal.values[0] and cal(2.0) == cal.values[-1] and cal(np.nan) == cal.values[0]
    held_out_raw, held_out_err = _synthetic(5000, np.random.default_rng(1))
    rows = reliability_table(cal(held_out_raw), held_out_err)
    assert len(rows) == 10 and sum(r["count"] for r in rows) == 5000
    gap = max(abs(r["mean_confidence"] - r["within_tolerance"]) for r in rows)
    assert gap < 0.06  # calibrated on held-out data: predicted matches observed per decile
    raw_rows = reliability_table(held_out_raw, held_out_err)
    assert max(abs(r["mean_confidence"] - r["within_tolerance"]) for r in raw_rows) > 0.15  # the raw score is not


def test_blocks_hold_at_least_min_per_knot_and_errors_are_clear(tmp_path):
    pytest.importorskip("sklearn", reason=NEEDS_SKLEARN)
    rng = np.random.default_rng(2)
    raw, errors = _synthetic(95, rng)
    cal = ConfidenceCalibration.fit(raw, errors, min_per_knot=20)
    assert len(cal.knots) <= 95 // 20 and cal.samples == 95
    back = ConfidenceCalibration.load(cal.save(tmp_path / "c.json"))
    assert back == cal
    with pytest.raises(ValueError, match="at least 40"):
        ConfidenceCalibration.fit(raw[:10], errors[:10])
    with pytest.raises(ValueError, match="must not decrease"):
        ConfidenceCalibration((0.1, 0.5), (0.8, 0.2))
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(ValueError, match="not a confidence calibration"):
        ConfidenceCalibration.load(tmp_path / "bad.json")


def test_undefined_estimates_count_as_misses_and_the_figure_draws(tmp_path):
    pytest.importorskip("sklearn", reason=NEEDS_SKLEARN)
    raw = np.r_[np.full(50, np.nan), np.full(50, 0.9)]
    errors = np.r_[np.full(50, np.nan), np.full(50, 1.0)]
    cal = ConfidenceCalibration.fit(raw, errors, min_per_knot=10)
    assert cal(0.0) == 0.0 and cal(0.9) == 1.0
    path = reliability_figure(reliability_table(cal(np.nan_to_num(raw)), errors, bins=5), tmp_path / "r.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_calibration_records_the_pose_aperture_it_was_fitted_with(tmp_path):
    import json

    pytest.importorskip("sklearn", reason=NEEDS_SKLEARN)
    raw, errors = _synthetic(200, np.random.default_rng(4))
    cal = ConfidenceCalibration.fit(raw, errors, aperture="none")
    back = ConfidenceCalibration.load(cal.save(tmp_path / "c.json"))
    assert back.aperture == "none" and back == cal
    assert not back.fits(prior_samples=1, symmetrized=False)  # the estimators' default is the disc
    assert back.fits(prior_samples=1, symmetrized=False, aperture="none")
    # a file written before the field existed was fitted with the whole-image moments
    old = {k: v for k, v in ConfidenceCalibration.fit(raw, errors).to_dict().items() if k != "aperture"}
    (tmp_path / "old.json").write_text(json.dumps(old))
    assert ConfidenceCalibration.load(tmp_path / "old.json").aperture == "none"


def test_blocks_are_the_pooled_runs_and_equal_neighbours_keep_a_knot_each():
    """Runs of min_per_knot sorted presses, pooled where they violate the order; two adjacent blocks of one
    mean stay two knots, so the curve is flat between them."""
    pytest.importorskip("sklearn", reason=NEEDS_SKLEARN)
    raw = np.arange(1, 81) / 100.0                        # four runs of 20: raw means 0.105, 0.305, 0.505, 0.705
    hits = np.r_[np.zeros(10), np.ones(10),               # run 1: 1/2
                 np.ones(15), np.zeros(5),                # run 2: 3/4
                 np.ones(5), np.zeros(15),                # run 3: 1/4 -> pooled with run 2: 1/2
                 np.ones(20)]                             # run 4: 1
    cal = ConfidenceCalibration.fit(raw, np.where(hits == 1, 1.0, 30.0), min_per_knot=20)
    np.testing.assert_allclose(cal.knots, [0.105, 0.405, 0.705])
    np.testing.assert_allclose(cal.values, [0.5, 0.5, 1.0])
    assert cal(0.3) == pytest.approx(0.5) and cal(0.555) == pytest.approx(0.75)


def test_applying_a_calibration_needs_no_sklearn_and_fitting_names_the_extra(tmp_path, monkeypatch):
    cal = ConfidenceCalibration((0.1, 0.9), (0.2, 0.8))
    path = cal.save(tmp_path / "c.json")
    monkeypatch.setitem(sys.modules, "sklearn", None)     # `import sklearn` now raises ImportError
    monkeypatch.setitem(sys.modules, "sklearn.isotonic", None)
    assert ConfidenceCalibration.load(path)(0.5) == pytest.approx(0.5)
    raw, errors = _synthetic(200, np.random.default_rng(5))
    with pytest.raises(MissingExtraError, match=r"fitting a calibration needs scikit-learn.*extra 'sklearn'"):
        ConfidenceCalibration.fit(raw, errors)


def test_a_sigma_map_gives_each_regime_of_the_models_sigma_its_own_scale() -> None:
    from tactile_manip.perception.confidence import ONE_SIGMA, SigmaCalibration

    rng = np.random.default_rng(0)
    # the model says 0.1 for a precise regime (errors 0.02) and 1.0 for a loose one (errors 1.5): one scale for
    # both would cover the first always and the second seldom
    sigma = np.r_[np.full(400, 0.1), np.full(400, 1.0)] * rng.uniform(0.9, 1.1, 800)
    err = np.abs(np.r_[rng.normal(0, 0.02, 400), rng.normal(0, 1.5, 400)])
    cal = SigmaCalibration.fit(sigma, err)
    inside = err <= cal(sigma)
    assert abs(inside[:400].mean() - ONE_SIGMA) < 0.06 and abs(inside[400:].mean() - ONE_SIGMA) < 0.06
    assert cal.samples == 800 and all(np.diff(cal.values) >= 0) and all(np.diff(cal.knots) > 0)
    # beyond the knots the ratio of the nearest knot holds; one() is the same map without arrays
    lo, hi = cal.knots[0] / 2, cal.knots[-1] * 3
    assert cal(lo) == pytest.approx(lo * cal.values[0] / cal.knots[0])
    assert cal(hi) == pytest.approx(hi * cal.values[-1] / cal.knots[-1])
    for s in (lo, 0.1, 0.5, 1.0, hi):
        assert cal.one(s) == pytest.approx(float(cal(s)))
    assert SigmaCalibration.from_dict(cal.to_dict()) == cal


def test_a_sigma_map_refuses_what_cannot_be_one() -> None:
    from tactile_manip.perception.confidence import SigmaCalibration

    with pytest.raises(ValueError, match="at least 40"):
        SigmaCalibration.fit(np.ones(10), np.ones(10))
    with pytest.raises(ValueError, match="increase"):
        SigmaCalibration(knots=(0.2, 0.1), values=(0.1, 0.2))
    with pytest.raises(ValueError, match="> 0"):
        SigmaCalibration(knots=(0.0, 0.1), values=(0.1, 0.2))
    # NaN sigmas or errors are left out of the fit, not spread into it
    sigma, err = np.r_[np.ones(60), np.nan], np.r_[np.full(60, 0.5), 1.0]
    assert SigmaCalibration.fit(sigma, err).samples == 60
