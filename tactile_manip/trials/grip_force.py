"""The grip force a run's contact model estimated, against the force the behaviour commanded (and applied).

Each record of a run whose scene names a ``contact_model`` carries ``estimated_grip_force_n`` with its sigma
(:class:`~tactile_manip.trials.record.TrialRecord`) and the behaviour's commanded grasp force
(``extra["commanded_force_n"]``). In simulation the force the twin applied is also known: the presentation's
force (``extra["force_n"]``, drawn per trial about the commanded threshold), which is the truth the estimate is
scored against there. On a real cell only the commanded force is known, and the real grip force differs from
it by the gripper's force control error.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from tactile_manip.trials.record import TrialRecord


@dataclass(frozen=True)
class GripForceSummary:
    """One method's estimated grip forces, N (None where a statistic has no data).

    Attributes:
        n: records with an estimate.
        commanded_n: mean commanded force over them.
        estimated_mean_n: mean estimate.
        error_mean_n: mean of estimate - commanded (the bias against the command).
        rmse_vs_commanded_n: RMS of estimate - commanded.
        sigma_mean_n: mean of the estimates' sigmas.
        applied: records with the applied force (simulation only; 0 when not scored against it).
        rmse_vs_applied_n: RMS of estimate - applied force.
        within_1_sigma: share of |estimate - applied| <= sigma (about 0.68 for calibrated sigmas).
    """

    method: str
    n: int
    commanded_n: float | None
    estimated_mean_n: float
    error_mean_n: float | None
    rmse_vs_commanded_n: float | None
    sigma_mean_n: float
    applied: int = 0
    rmse_vs_applied_n: float | None = None
    within_1_sigma: float | None = None


def grip_force_summary(records: Iterable[TrialRecord], *, applied: bool = False) -> dict[str, GripForceSummary]:
    """Per method (in order of first appearance), the records that carry an estimated grip force; methods
    without one are left out (an empty dict for a run without a contact model).

    ``applied``: also score against the force a simulated cell applied (``extra["applied_force_n"]`` where a
    grip logs it, else ``extra["force_n"]``) (a real cell
    logs the presentation's drawn force there, which nobody applied: leave it False for real runs).
    """
    by_method: dict[str, list[TrialRecord]] = {}
    for r in records:
        if r.estimated_grip_force_n is not None:
            by_method.setdefault(r.method, []).append(r)
    return {m: _summary(m, recs, applied) for m, recs in by_method.items()}


def _summary(method: str, recs: list[TrialRecord], applied: bool) -> GripForceSummary:
    est = np.array([r.estimated_grip_force_n for r in recs], np.float64)
    sigma = np.array([r.estimated_grip_force_sigma_n for r in recs], np.float64)
    commanded = np.array([r.extra.get("commanded_force_n", math.nan) for r in recs], np.float64)
    known = np.isfinite(commanded)
    err = est[known] - commanded[known]
    out = {"commanded_n": _mean(commanded[known]), "error_mean_n": _mean(err), "rmse_vs_commanded_n": _rms(err)}
    if applied:
        truth = np.array([_applied(r) for r in recs], np.float64)
        has = np.isfinite(truth)
        miss = est[has] - truth[has]
        out.update(applied=int(has.sum()), rmse_vs_applied_n=_rms(miss),
                   within_1_sigma=float(np.mean(np.abs(miss) <= sigma[has])) if has.any() else None)
    return GripForceSummary(method=method, n=len(recs), estimated_mean_n=float(est.mean()),
                            sigma_mean_n=float(sigma.mean()), **out)


def markdown_lines(summary: dict[str, GripForceSummary]) -> list[str]:
    """The summary's markdown section (no lines when no method has an estimate)."""
    if not summary:
        return []
    applied = any(s.applied for s in summary.values())
    header = ["method", "estimates", "commanded (N)", "mean estimate (N)", "mean error (N)", "RMSE vs commanded (N)",
              "mean sigma (N)"]
    if applied:
        header += ["RMSE vs applied (N)", "within 1 sigma of applied"]
    rows = []
    for m, s in summary.items():
        row = [m, str(s.n), _n(s.commanded_n), _n(s.estimated_mean_n), _n(s.error_mean_n, sign=True),
               _n(s.rmse_vs_commanded_n), _n(s.sigma_mean_n)]
        if applied:
            row += [_n(s.rmse_vs_applied_n), "-" if s.within_1_sigma is None else f"{100 * s.within_1_sigma:.0f} %"]
        rows.append(row)
    note = ("estimated by the method's contact model (the scene's unless the method names its own) at the estimate "
            "step; error = estimate - commanded"
            + ("; applied: the force the simulated cell applied" if applied else ""))
    return ["", "## Estimated grip force", "", note + ".", "",
            "| " + " | ".join(header) + " |", "|" + "---|" * len(header),
            *("| " + " | ".join(row) + " |" for row in rows)]


def _applied(r: TrialRecord) -> float:
    """The force the simulated cell applied at the estimate: a grip logs it after its corrections
    (``applied_force_n``), the other tasks apply the presentation's force throughout."""
    value = r.extra.get("applied_force_n", r.extra.get("force_n"))
    return math.nan if value is None else float(value)


def _mean(x: np.ndarray) -> float | None:
    return float(x.mean()) if x.size else None


def _rms(x: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(x ** 2))) if x.size else None


def _n(x: float | None, *, sign: bool = False) -> str:
    return "-" if x is None else (f"{x:+.2f}" if sign else f"{x:.2f}")
