"""Scoring: Wilson intervals and exact McNemar against independent computations, and ``summarise`` on a
hand-made paired run whose every number is worked out below."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from tactile_manip.trials.record import TrialRecord
from tactile_manip.trials.stats import mcnemar_exact, success_vs_tolerance, summarise, wilson_interval

OBJECTS = ("allen_key",) * 3 + ("letter_r",) * 3
# supermag: all executed; |error| 1, 2, 3, 4.5, 7, 0.5 deg
SUPERMAG = [("done", 1.0), ("done", -2.0), ("done", 3.0), ("done", 4.5), ("done", -7.0), ("done", 0.5)]
# bilinear: executed 12, -4, 30 deg; one abstention, one missed grasp, one IK failure
BILINEAR = [("done", 12.0), ("abstained", None), ("done", -4.0), ("grasp_failed", None), ("done", 30.0),
            ("ik_failed", None)]


def make_record(trial: int, method: str, outcome: str, error_deg: float | None, *, confidence: float = 0.8,
                seed: int | None = None, obj: str | None = None) -> TrialRecord:
    error = None if error_deg is None else math.radians(error_deg)
    return TrialRecord(trial=trial, seed=1000 + trial if seed is None else seed, method=method,
                       object=OBJECTS[trial] if obj is None else obj, true_angle_rad=0.3, offset_mm=(0.5, -1.0),
                       target_angle_rad=0.0, estimated_angle_rad=0.29, confidence=confidence, defined=True,
                       final_angle_rad=error, error_rad=error, outcome=outcome)


def paired_run() -> list[TrialRecord]:
    recs = [make_record(i, "supermag", o, e, confidence=0.9) for i, (o, e) in enumerate(SUPERMAG)]
    return recs + [make_record(i, "bilinear", o, e, confidence=0.3) for i, (o, e) in enumerate(BILINEAR)]


# ---------------------------------------------------------------- Wilson


@pytest.mark.parametrize("k, n, expected", [
    (6, 6, (0.610, 1.000)),   # the paper's 6/6
    (1, 6, (0.030, 0.564)),   # the paper's baseline 1/6
    (95, 100, (0.888, 0.978)),
    (0, 10, (0.000, 0.278)),
])
def test_wilson_matches_published_values(k, n, expected):
    low, high = wilson_interval(k, n)
    assert (round(low, 3), round(high, 3)) == expected


@pytest.mark.parametrize("k, n", [(1, 6), (3, 7), (50, 100), (99, 100)])
def test_wilson_bounds_are_where_the_score_test_hits_z(k, n):
    """Independent of the closed form: each bound p solves |k/n - p| = z sqrt(p (1 - p) / n)."""
    z = 1.959963984540054
    score = lambda p: abs(k / n - p) - z * math.sqrt(p * (1 - p) / n)  # noqa: E731
    low, high = wilson_interval(k, n)
    assert low == pytest.approx(brentq(score, 1e-12, k / n), abs=1e-9)
    assert high == pytest.approx(brentq(score, k / n, 1 - 1e-12), abs=1e-9)


def test_wilson_edges():
    assert wilson_interval(0, 0) == (0.0, 1.0)
    assert wilson_interval(0, 5)[0] == 0.0
    assert wilson_interval(5, 5)[1] == 1.0
    narrow, wide = wilson_interval(3, 10, 0.90), wilson_interval(3, 10, 0.99)
    assert wide[0] < narrow[0] < 0.3 < narrow[1] < wide[1]


@pytest.mark.parametrize("k, n, conf, match", [(7, 6, 0.95, r"0 <= successes <= n, got successes=7, n=6"),
                                              (-1, 6, 0.95, r"0 <= successes <= n, got successes=-1"),
                                              (1, 6, 1.0, r"confidence must be in \(0, 1\), got 1.0"),
                                              (1.5, 6, 0.95, r"successes and n must be integers, got 1.5")],
                         ids=["more successes than trials", "negative successes", "confidence 1", "not an integer"])
def test_wilson_refuses_bad_input(k, n, conf, match):
    with pytest.raises(ValueError, match=match):
        wilson_interval(k, n, conf)


# ---------------------------------------------------------------- McNemar


def _mcnemar_by_enumeration(b: int, c: int) -> float:
    """Sum of Binomial(n, 1/2) probabilities of every split at least as unbalanced as (b, c)."""
    n = b + c
    return sum(math.comb(n, i) for i in range(n + 1) if abs(2 * i - n) >= abs(b - c)) / 2 ** n


def test_mcnemar_known_values():
    assert mcnemar_exact(0, 6) == pytest.approx(0.03125)
    assert mcnemar_exact(6, 0) == pytest.approx(0.03125)
    assert mcnemar_exact(0, 0) == 1.0
    assert mcnemar_exact(3, 3) == 1.0


@pytest.mark.parametrize("b, c", [(1, 5), (2, 9), (10, 4), (0, 1), (7, 7), (20, 31)])
def test_mcnemar_matches_enumeration_and_is_symmetric(b, c):
    assert mcnemar_exact(b, c) == pytest.approx(_mcnemar_by_enumeration(b, c))
    assert mcnemar_exact(b, c) == mcnemar_exact(c, b)


# ---------------------------------------------------------------- summarise


def test_summary_per_method_at_5_deg():
    s = summarise(paired_run(), math.radians(5.0))
    assert list(s.methods) == ["supermag", "bilinear"]
    assert s.tolerance_deg == pytest.approx(5.0) and s.n_records == 12
    sm, bl = s.methods["supermag"], s.methods["bilinear"]
    assert (sm.n, sm.successes, sm.executed, sm.abstentions, sm.faults) == (6, 5, 6, 0, 0)
    assert (bl.n, bl.successes, bl.executed, bl.abstentions, bl.faults) == (6, 1, 3, 1, 2)
    assert (sm.wilson_low, sm.wilson_high) == wilson_interval(5, 6)
    assert bl.success_rate == pytest.approx(1 / 6)
    assert bl.outcomes == {"done": 3, "abstained": 1, "grasp_failed": 1, "sensor_stale": 0, "ik_failed": 1,
                           "arm_fault": 0, "safety_refused": 0, "unmeasured": 0, "error": 0}
    assert sm.abs_error_median_deg == pytest.approx(2.5)
    assert sm.abs_error_max_deg == pytest.approx(7.0)
    assert bl.abs_error_median_deg == pytest.approx(12.0)
    assert bl.abs_error_p95_deg == pytest.approx(12.0 + 0.9 * 18.0)  # linear interpolation in [4, 12, 30]
    assert sm.mean_confidence == pytest.approx(0.9) and bl.mean_confidence == pytest.approx(0.3)


def test_paired_comparison_and_rescoring_at_two_tolerances():
    at5 = summarise(paired_run(), math.radians(5.0)).paired
    at10 = summarise(paired_run(), math.radians(10.0)).paired
    assert len(at5) == 1
    p = at5[0]
    assert (p.method_a, p.method_b, p.n_pairs) == ("supermag", "bilinear", 6)
    assert (p.both, p.only_a, p.only_b, p.neither) == (1, 4, 0, 1)  # trial 4: supermag 7 deg, bilinear 30
    assert p.mcnemar_p == pytest.approx(mcnemar_exact(4, 0)) == pytest.approx(0.125)
    q = at10[0]
    assert (q.both, q.only_a, q.only_b, q.neither) == (1, 5, 0, 0)
    assert q.mcnemar_p == pytest.approx(0.0625)
    assert summarise(paired_run(), math.radians(10.0)).methods["supermag"].successes == 6
    assert summarise(paired_run(), math.radians(15.0)).methods["bilinear"].successes == 2


def test_per_object_counts():
    s = summarise(paired_run(), math.radians(5.0))
    assert {o: {m: tuple(c) for m, c in by.items()} for o, by in s.per_object.items()} == {
        "allen_key": {"supermag": (3, 3), "bilinear": (1, 3)},
        "letter_r": {"supermag": (2, 3), "bilinear": (0, 3)},
    }


def test_summary_to_dict_is_json():
    d = json.loads(json.dumps(summarise(paired_run(), math.radians(5.0)).to_dict(), allow_nan=False))
    assert d["methods"]["bilinear"]["successes"] == 1
    assert d["per_object"]["letter_r"]["supermag"] == {"successes": 2, "n": 3}
    assert d["paired"][0]["only_a"] == 4


def test_method_without_executed_trials_has_no_error_statistics():
    recs = [make_record(i, "bilinear", "abstained", None, confidence=0.0) for i in range(3)]
    m = summarise(recs, math.radians(5.0)).methods["bilinear"]
    assert (m.successes, m.abstentions, m.abs_error_median_deg, m.abs_error_max_deg) == (0, 3, None, None)


def test_pairs_only_the_trials_both_methods_ran():
    recs = paired_run()[:-1]  # bilinear's trial 5 was never run
    p = summarise(recs, math.radians(5.0)).paired[0]
    assert p.n_pairs == 5 and (p.both, p.only_a, p.only_b, p.neither) == (1, 3, 0, 1)


def test_summarise_refuses_inconsistent_runs():
    with pytest.raises(ValueError, match="no trial records"):
        summarise([], 0.1)
    with pytest.raises(ValueError, match="tolerance_rad"):
        summarise(paired_run(), -0.1)
    with pytest.raises(ValueError, match="logged twice"):
        summarise(paired_run() + [make_record(0, "supermag", "done", 1.0)], 0.1)
    clash = [make_record(0, "supermag", "done", 1.0), make_record(0, "bilinear", "done", 1.0, seed=7)]
    with pytest.raises(ValueError, match="same presentations"):
        summarise(clash, 0.1)


def test_success_vs_tolerance_matches_summarise():
    recs = paired_run()
    tolerances_deg = np.array([0.0, 5.0, 10.0, 15.0, 40.0])
    rates = success_vs_tolerance(recs, np.radians(tolerances_deg))
    np.testing.assert_allclose(rates["supermag"], [0, 5 / 6, 1, 1, 1])
    np.testing.assert_allclose(rates["bilinear"], [0, 1 / 6, 1 / 6, 2 / 6, 3 / 6])
    for t, rs, rb in zip(tolerances_deg, rates["supermag"], rates["bilinear"]):
        s = summarise(recs, math.radians(t))
        assert (s.methods["supermag"].success_rate, s.methods["bilinear"].success_rate) == (rs, rb)
