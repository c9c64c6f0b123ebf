"""Scoring a run: success rates with Wilson intervals, paired comparisons (exact McNemar), error statistics.

A trial succeeds at a tolerance when its outcome is ``"done"`` and ``|error_rad| <= tolerance``
(``TrialRecord.succeeded``), so a run is re-scored at any tolerance from its records alone. Methods are
compared pairwise on the trial indices both ran (the same seeds, hence the same presentations).

Records hold radians; the summary holds degrees for reading (every such name ends in ``_deg``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from typing import Any, NamedTuple

import numpy as np
from scipy import stats as _sp

from tactile_manip.trials.record import OUTCOMES, TrialRecord


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (scipy's ``binomtest(...).proportion_ci``, no continuity
    correction).

    Args:
        successes: number of successes, 0 <= successes <= n.
        n: number of trials, >= 0.
        confidence: two-sided confidence level in (0, 1).

    Returns:
        (low, high) in [0, 1]; (0, 1) when n == 0 (nothing is known); low is exactly 0 at 0/n and high exactly
        1 at n/n.
    """
    if not (isinstance(n, (int, np.integer)) and isinstance(successes, (int, np.integer))):
        raise ValueError(f"successes and n must be integers, got {successes!r} and {n!r}")
    if not 0 <= successes <= n:
        raise ValueError(f"expected 0 <= successes <= n, got successes={successes}, n={n}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    if n == 0:
        return 0.0, 1.0
    ci = _sp.binomtest(int(successes), int(n)).proportion_ci(confidence_level=confidence, method="wilson")
    low = 0.0 if successes == 0 else max(0.0, float(ci.low))
    high = 1.0 if successes == n else min(1.0, float(ci.high))
    return low, high


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar test: p-value of ``b`` vs ``c`` discordant pairs under Binomial(b + c, 1/2).

    ``b`` counts pairs where only the first method succeeded, ``c`` where only the second did. Returns 1.0
    when there is no discordant pair. Symmetric in (b, c).
    """
    if min(b, c) < 0:
        raise ValueError(f"discordant counts must be >= 0, got b={b}, c={c}")
    n = b + c
    if n == 0:
        return 1.0
    return float(min(1.0, 2.0 * _sp.binom.cdf(min(b, c), n, 0.5)))


class Count(NamedTuple):
    """Successes out of n trials."""

    successes: int
    n: int


@dataclass(frozen=True)
class MethodSummary:
    """One method's results at a tolerance (angles in degrees).

    ``faults`` counts trials that ended neither ``"done"`` nor ``"abstained"`` (grasp, sensor, IK, arm,
    safety or other errors). Error statistics are over executed (``"done"``) trials and None when there is
    none. ``mean_confidence`` is over all the method's trials (0 where the estimate was undefined or never
    reached, as logged).
    """

    method: str
    n: int
    successes: int
    success_rate: float
    wilson_low: float
    wilson_high: float
    outcomes: dict[str, int]
    executed: int
    abstentions: int
    faults: int
    abs_error_median_deg: float | None
    abs_error_p95_deg: float | None
    abs_error_max_deg: float | None
    mean_confidence: float


@dataclass(frozen=True)
class PairedComparison:
    """Two methods on the trials both ran: success in both, only in A, only in B, in neither; exact McNemar p."""

    method_a: str
    method_b: str
    n_pairs: int
    both: int
    only_a: int
    only_b: int
    neither: int
    mcnemar_p: float


@dataclass(frozen=True)
class RunSummary:
    """A run scored at ``tolerance_deg``: per-method results (in the order methods first appear in the log),
    a comparison for every pair of methods, and per-object counts ``per_object[object][method]``."""

    tolerance_deg: float
    n_records: int
    methods: dict[str, MethodSummary]
    paired: list[PairedComparison]
    per_object: dict[str, dict[str, Count]]

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON data (None where a statistic is undefined)."""
        return {
            "tolerance_deg": self.tolerance_deg,
            "n_records": self.n_records,
            "methods": {m: asdict(s) for m, s in self.methods.items()},
            "paired": [asdict(p) for p in self.paired],
            "per_object": {o: {m: c._asdict() for m, c in by.items()} for o, by in self.per_object.items()},
        }


def summarise(records: Iterable[TrialRecord], tolerance_rad: float) -> RunSummary:
    """Score ``records`` at ``tolerance_rad``.

    Raises:
        ValueError: no records; a bad tolerance; the same (trial, method) twice; or one trial index with
            different seeds or objects across methods (not the same presentation, so no paired comparison).
    """
    records = list(records)
    _check_tolerance(tolerance_rad)
    if not records:
        raise ValueError("no trial records to summarise")
    by_method = _by_method(records)
    _check_pairing(by_method)
    methods = {m: _method_summary(m, list(recs.values()), tolerance_rad) for m, recs in by_method.items()}
    paired = [_paired(a, b, by_method[a], by_method[b], tolerance_rad)
              for a, b in itertools.combinations(by_method, 2)]
    per_object: dict[str, dict[str, Count]] = {}
    for obj in dict.fromkeys(r.object for r in records):
        per_object[obj] = {}
        for m, recs in by_method.items():
            mine = [r for r in recs.values() if r.object == obj]
            if mine:
                per_object[obj][m] = Count(sum(r.succeeded(tolerance_rad) for r in mine), len(mine))
    return RunSummary(tolerance_deg=math.degrees(tolerance_rad), n_records=len(records), methods=methods,
                      paired=paired, per_object=per_object)


def success_vs_tolerance(records: Iterable[TrialRecord], tolerances_rad: Sequence[float] | np.ndarray
                         ) -> dict[str, np.ndarray]:
    """Success rate of each method at each tolerance: ``{method: rates}``, rates of shape (len(tolerances),)."""
    tol = np.asarray(tolerances_rad, dtype=np.float64).reshape(-1)
    for t in tol:
        _check_tolerance(float(t))
    out = {}
    for m, recs in _by_method(list(records)).items():
        errors = np.sort([abs(r.error_rad) for r in recs.values() if r.outcome == "done" and r.within_clearance
                          and r.within_force])
        out[m] = np.searchsorted(errors, tol, side="right") / len(recs)  # count of |error| <= t, over n
    return out


def _check_tolerance(tolerance_rad: float) -> None:
    if not (math.isfinite(tolerance_rad) and tolerance_rad >= 0.0):
        raise ValueError(f"tolerance_rad must be finite and >= 0, got {tolerance_rad}")


def _by_method(records: list[TrialRecord]) -> dict[str, dict[int, TrialRecord]]:
    """{method: {trial: record}}, methods in order of first appearance; a repeated (trial, method) raises."""
    out: dict[str, dict[int, TrialRecord]] = {}
    for r in records:
        mine = out.setdefault(r.method, {})
        if r.trial in mine:
            raise ValueError(f"trial {r.trial} of method {r.method!r} is logged twice; a run logs each once")
        mine[r.trial] = r
    return out


def _check_pairing(by_method: dict[str, dict[int, TrialRecord]]) -> None:
    first: dict[int, TrialRecord] = {}
    for recs in by_method.values():
        for t, r in recs.items():
            f = first.setdefault(t, r)
            if (f.seed, f.object) != (r.seed, r.object):
                raise ValueError(f"trial {t} is seed {f.seed} ({f.object}) for {f.method!r} but seed {r.seed} "
                                 f"({r.object}) for {r.method!r}: methods must run the same presentations")


def _method_summary(method: str, recs: list[TrialRecord], tolerance_rad: float) -> MethodSummary:
    n = len(recs)
    k = sum(r.succeeded(tolerance_rad) for r in recs)
    outcomes = {o: sum(r.outcome == o for r in recs) for o in OUTCOMES}
    abs_err_deg = np.degrees([abs(r.error_rad) for r in recs if r.outcome == "done"])
    low, high = wilson_interval(k, n)

    def stat(f) -> float | None:
        return float(f(abs_err_deg)) if abs_err_deg.size else None

    return MethodSummary(
        method=method, n=n, successes=k, success_rate=k / n, wilson_low=low, wilson_high=high,
        outcomes=outcomes, executed=outcomes["done"], abstentions=outcomes["abstained"],
        faults=n - outcomes["done"] - outcomes["abstained"],
        abs_error_median_deg=stat(np.median), abs_error_p95_deg=stat(lambda e: np.percentile(e, 95)),
        abs_error_max_deg=stat(np.max), mean_confidence=float(np.mean([r.confidence for r in recs])))


def _paired(a: str, b: str, recs_a: dict[int, TrialRecord], recs_b: dict[int, TrialRecord],
            tolerance_rad: float) -> PairedComparison:
    shared = sorted(recs_a.keys() & recs_b.keys())
    sa = [recs_a[t].succeeded(tolerance_rad) for t in shared]
    sb = [recs_b[t].succeeded(tolerance_rad) for t in shared]
    both = sum(x and y for x, y in zip(sa, sb))
    only_a = sum(x and not y for x, y in zip(sa, sb))
    only_b = sum(y and not x for x, y in zip(sa, sb))
    return PairedComparison(method_a=a, method_b=b, n_pairs=len(shared), both=both, only_a=only_a,
                            only_b=only_b, neither=len(shared) - both - only_a - only_b,
                            mcnemar_p=mcnemar_exact(only_a, only_b))
