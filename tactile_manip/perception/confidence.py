"""Confidence that predicts error: calibrate the pose estimate's raw confidence against held-out errors.

The raw confidence of an :class:`~tactile_manip.types.AngleEstimate` (``1 - lambda_minor / lambda_major`` of the
contact's moments, times the agreement of prior samples when the model draws several, times the fraction of
unsaturated chips) orders estimates by how elongated and consistent the contact looks; it is not a
probability. :class:`ConfidenceCalibration` maps it monotonically onto the probability that the angle error is
within ``tolerance_deg``, fitted by isotonic regression (scikit-learn's, the ``calibration`` extra) on held-out
presses, so a behaviour's ``min_confidence = 0.9`` means "act when 9 in 10 such estimates were within
tolerance". Applying a fitted calibration needs numpy only.

:func:`reliability_table` bins estimates by confidence (deciles by default) and reports, per bin, the mean
predicted probability, the observed share within tolerance and the median / p95 error: the reliability
diagram in numbers. numpy only (the figure needs matplotlib).

A model's calibration lives beside it as ``<model>.calibration.json`` (:func:`calibration_path`; written by
``tactile-manip calibrate``); :func:`load_calibration_beside` finds it.

The contact model's sigmas are calibrated by the same mechanism: :class:`SigmaCalibration` orders held-out
samples by the model's own uncertainty, fits one value per run of them and makes those monotone by isotonic
regression (:func:`run_starts`, :func:`isotonic_in_order`), mapping the model's sigma onto one that holds
68.3 % of the errors; the contact export carries it and :class:`~tactile_manip.perception.contact.ContactEstimator`
applies it.
"""

from __future__ import annotations

import bisect
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.extras import require


@dataclass(frozen=True)
class ConfidenceCalibration:
    """A non-decreasing piecewise-linear map raw confidence -> P(|error| <= tolerance_deg)."""

    knots: tuple[float, ...]      # raw confidence at the breakpoints, ascending, in [0, 1]
    values: tuple[float, ...]     # calibrated probability at the knots, non-decreasing, in [0, 1]
    tolerance_deg: float = 5.0    # the error the probability is about, deg
    samples: int = 0              # held-out estimates it was fitted on
    prior_samples: int = 1        # prior samples per reading of the estimator it was fitted for
    symmetrized: bool = False     # fitted for the model averaged over the sensor's symmetries
    aperture: str = "disc"        # the pose pipeline's moments aperture it was fitted with (PoseParams.aperture)
    route: str = "image"          # the estimator's angle route it was fitted for ("image", "head", "likelier")

    def __post_init__(self) -> None:
        k, v = np.asarray(self.knots, float), np.asarray(self.values, float)
        if k.ndim != 1 or k.size < 1 or k.shape != v.shape:
            raise ValueError(f"knots and values must be 1-D of one length >= 1, got {k.shape} and {v.shape}")
        if not (np.isfinite(k).all() and np.isfinite(v).all()):
            raise ValueError("knots and values must be finite")
        if np.any(np.diff(k) <= 0) or np.any(np.diff(v) < 0):
            raise ValueError("knots must increase and values must not decrease")
        if k.min() < 0 or k.max() > 1 or v.min() < 0 or v.max() > 1:
            raise ValueError("knots and values must lie in [0, 1]")
        if not (math.isfinite(self.tolerance_deg) and self.tolerance_deg > 0):
            raise ValueError(f"tolerance_deg must be finite and > 0, got {self.tolerance_deg}")

    def __call__(self, raw: float | np.ndarray) -> float | np.ndarray:
        """Calibrated probability for raw confidence(s); NaN maps to the lowest value."""
        r = np.nan_to_num(np.asarray(raw, float), nan=-1.0)
        out = np.interp(r, self.knots, self.values)
        return float(out) if out.ndim == 0 else out

    def fits(self, *, prior_samples: int, symmetrized: bool, aperture: str = "disc", route: str = "image") -> bool:
        """Whether it was fitted for an estimator with these settings (the raw confidence of another is
        distributed otherwise, so this map would not give its probability). The angle head's reading does not
        depend on the image's prior samples or symmetry averaging, so for the "head" route those do not count."""
        image = route == "head" or (self.prior_samples == prior_samples and self.symmetrized == symmetrized
                                    and self.aperture == aperture)
        return self.route == route and image

    @classmethod
    def fit(cls, raw: np.ndarray, errors_deg: np.ndarray, *, tolerance_deg: float = 5.0,
            min_per_knot: int = 20, prior_samples: int = 1, symmetrized: bool = False,
            aperture: str = "disc", route: str = "image") -> ConfidenceCalibration:
        """Isotonic fit of "error within tolerance" on raw confidence (held-out estimates only).

        Undefined estimates enter with raw confidence 0 and their error (90 deg when unknown). Blocks of fewer
        than ``min_per_knot`` estimates are merged into their neighbours, so a knot is never a single press.
        """
        raw = np.clip(np.nan_to_num(np.asarray(raw, float), nan=0.0), 0.0, 1.0)
        err = np.nan_to_num(np.abs(np.asarray(errors_deg, float)), nan=90.0)
        if raw.shape != err.shape or raw.ndim != 1 or raw.size < 2 * min_per_knot:
            raise ValueError(f"need matching 1-D raw confidences and errors, at least {2 * min_per_knot}; got "
                             f"{raw.shape} and {err.shape}")
        order = np.argsort(raw, kind="stable")
        x, y = raw[order], (err[order] <= tolerance_deg).astype(float)
        blocks = _isotonic_blocks(x, y, min_per_knot)
        knots = [b[0] for b in blocks]
        values = [b[1] for b in blocks]
        knots, values = _strictly_increasing([min(max(k, 0.0), 1.0) for k in knots], values)
        return cls(tuple(knots), tuple(values), float(tolerance_deg), int(raw.size), int(prior_samples),
                   bool(symmetrized), str(aperture), str(route))

    def to_dict(self) -> dict[str, Any]:
        return {"knots": list(self.knots), "values": list(self.values), "tolerance_deg": self.tolerance_deg,
                "samples": self.samples, "prior_samples": self.prior_samples, "symmetrized": self.symmetrized,
                "aperture": self.aperture, "route": self.route}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ConfidenceCalibration:
        # a file without "aperture" predates it: it was fitted with the whole-image moments; one without "route"
        # predates the angle head: fitted on the image's angles
        return cls(tuple(d["knots"]), tuple(d["values"]), float(d["tolerance_deg"]), int(d.get("samples", 0)),
                   int(d.get("prior_samples", 1)), bool(d.get("symmetrized", False)), str(d.get("aperture", "none")),
                   str(d.get("route", "image")))

    def save(self, path: str | Path) -> Path:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(self.to_dict(), indent=1))
        return Path(path)

    @classmethod
    def load(cls, path: str | Path) -> ConfidenceCalibration:
        try:
            return cls.from_dict(json.loads(Path(path).read_text()))
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise ValueError(f"{path}: not a confidence calibration ({type(e).__name__}: {e})") from e


def calibration_path(model_path: str | Path) -> Path:
    """Where the calibration of the model at ``model_path`` lives: ``models/x.onnx`` -> ``models/x.calibration.json``."""
    p = Path(model_path)
    return p.with_name(f"{p.stem}.calibration.json")


def load_calibration_beside(model_path: str | Path) -> ConfidenceCalibration | None:
    """The calibration beside the model at ``model_path``, None when it has none (ValueError when unreadable)."""
    path = calibration_path(model_path)
    return ConfidenceCalibration.load(path) if path.is_file() else None


def run_starts(n: int, min_count: int) -> np.ndarray:
    """Starts of the runs of ``min_count`` consecutive held-out samples (of ``n``) that every calibration here
    fits one value to; a short tail joins the last run."""
    starts = np.arange(0, n, min_count)
    if starts.size > 1 and n - starts[-1] < min_count:
        starts = starts[:-1]
    return starts


def isotonic_in_order(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The non-decreasing least-squares fit of ``values`` in their order, weighted (scikit-learn's
    IsotonicRegression, extra ``sklearn``): the one fit behind the angle's confidence and the contact's sigma."""
    isotonic = require("sklearn.isotonic", "fitting a calibration")
    return isotonic.IsotonicRegression().fit_transform(np.arange(len(values), dtype=np.float64),
                                                       np.asarray(values, np.float64), sample_weight=weights)


#: share of a calibrated Gaussian's errors within one sigma
ONE_SIGMA = 0.6827


@dataclass(frozen=True)
class SigmaCalibration:
    """A non-decreasing map from a model's sigma of one target to a sigma that holds :data:`ONE_SIGMA` of the
    held-out errors wherever the model's sigma lies (not only on average): the contact model's counterpart of
    :class:`ConfidenceCalibration`, fitted by the same isotonic regression over runs of held-out samples.

    A single scale per target is right on average over the held-out samples and wrong wherever their mix
    differs: on the eFlesh force run, readings without load (a sigma the model already makes small) are far
    more precise than it says, readings under load less. Between the knots the map is linear; beyond them it
    keeps the ratio of the nearest knot (a sigma twice the last knot's maps to twice its value).
    """

    knots: tuple[float, ...]      # the model's sigma, ascending, > 0
    values: tuple[float, ...]     # the calibrated sigma there, non-decreasing, > 0
    samples: int = 0              # held-out samples it was fitted on

    def __post_init__(self) -> None:
        k, v = np.asarray(self.knots, float), np.asarray(self.values, float)
        if k.ndim != 1 or k.size < 1 or k.shape != v.shape:
            raise ValueError(f"knots and values must be 1-D of one length >= 1, got {k.shape} and {v.shape}")
        if not (np.isfinite(k).all() and np.isfinite(v).all()) or k.min() <= 0 or v.min() <= 0:
            raise ValueError("knots and values must be finite and > 0")
        if np.any(np.diff(k) <= 0) or np.any(np.diff(v) < 0):
            raise ValueError("knots must increase and values must not decrease")

    def __call__(self, sigma: float | np.ndarray) -> np.ndarray:
        s = np.asarray(sigma, np.float64)
        k, v = self.knots, self.values
        return np.where(s < k[0], s * (v[0] / k[0]), np.where(s > k[-1], s * (v[-1] / k[-1]), np.interp(s, k, v)))

    def one(self, sigma: float) -> float:
        """The map of one sigma, in plain Python (a control loop's call: no array is made)."""
        k, v = self.knots, self.values
        if sigma <= k[0]:
            return sigma * v[0] / k[0]
        if sigma >= k[-1]:
            return sigma * v[-1] / k[-1]
        i = bisect.bisect_right(k, sigma)
        t = (sigma - k[i - 1]) / (k[i] - k[i - 1])
        return v[i - 1] + t * (v[i] - v[i - 1])

    @classmethod
    def fit(cls, sigma: np.ndarray, abs_error: np.ndarray, *, min_per_knot: int = 40) -> SigmaCalibration:
        """Order the held-out samples by the model's sigma, take runs of ``min_per_knot``, give each run the
        sigma that holds :data:`ONE_SIGMA` of its errors (its mean sigma times the quantile of error / sigma),
        and fit those in order by isotonic regression (:func:`isotonic_in_order`)."""
        sigma = np.asarray(sigma, np.float64)
        err = np.abs(np.asarray(abs_error, np.float64))
        ok = np.isfinite(sigma) & np.isfinite(err) & (sigma > 0)
        if sigma.shape != err.shape or sigma.ndim != 1 or ok.sum() < min_per_knot:
            raise ValueError(f"need matching 1-D sigmas and errors with at least {min_per_knot} finite pairs; got "
                             f"{sigma.shape}, {err.shape} ({int(ok.sum())} finite)")
        sigma, err = sigma[ok], err[ok]
        order = np.argsort(sigma, kind="stable")
        sigma, ratio = sigma[order], err[order] / sigma[order]
        starts = run_starts(sigma.size, min_per_knot)
        ends = np.append(starts[1:], sigma.size)
        knots = np.array([sigma[a:b].mean() for a, b in zip(starts, ends)])
        local = np.array([np.quantile(ratio[a:b], ONE_SIGMA) for a, b in zip(starts, ends)]) * knots
        values = np.maximum(isotonic_in_order(local, (ends - starts).astype(np.float64)), 1e-12)
        knots, values = _strictly_increasing(knots.tolist(), values.tolist())   # tied sigmas: the higher value
        return cls(tuple(knots), tuple(values), int(sigma.size))

    def to_dict(self) -> dict[str, Any]:
        return {"knots": list(self.knots), "values": list(self.values), "samples": self.samples}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SigmaCalibration:
        return cls(tuple(d["knots"]), tuple(d["values"]), int(d.get("samples", 0)))


def _isotonic_blocks(x: np.ndarray, y: np.ndarray, min_count: int) -> list[tuple[float, float]]:
    """Blocks (mean x, mean y) of the isotonic regression of 0/1 y on sorted x, each of >= min_count points.

    The sorted points are first grouped into runs of ``min_count`` (a short tail joins the last run); scikit-learn's
    IsotonicRegression fits the runs' mean y in their order (by rank, so runs of tied raw confidence stay
    separate points), weighted by their sizes. A stretch of runs it gives one value is then cut wherever its
    running mean returns to that value: adjacent blocks of equal mean keep a knot each, so the interpolated curve
    stays flat across a plateau instead of one knot at its middle.
    """
    starts = run_starts(x.size, min_count)
    counts = np.diff(np.append(starts, x.size)).astype(np.float64)
    sum_x, sum_y = np.add.reduceat(x, starts), np.add.reduceat(y, starts)
    fitted = isotonic_in_order(sum_y / counts, counts)
    new_value = np.r_[True, fitted[1:] != fitted[:-1]]
    first, stretch = np.flatnonzero(new_value), np.cumsum(new_value) - 1
    total_y, total_n = np.add.reduceat(sum_y, first)[stretch], np.add.reduceat(counts, first)[stretch]
    cum_y, cum_n = np.cumsum(sum_y), np.cumsum(counts)
    run_y = cum_y - np.r_[0.0, cum_y][first][stretch]          # sums from the stretch's first run on
    run_n = cum_n - np.r_[0.0, cum_n][first][stretch]
    ends = np.isclose(run_y * total_n, total_y * run_n, rtol=0.0, atol=1e-6)   # y sums are counts: exact
    ends[np.r_[first[1:] - 1, starts.size - 1]] = True
    cut = np.r_[0, np.flatnonzero(ends)[:-1] + 1]
    n = np.add.reduceat(counts, cut)
    return [(float(bx / bn), float(by / bn))
            for bx, by, bn in zip(np.add.reduceat(sum_x, cut), np.add.reduceat(sum_y, cut), n)]


def _strictly_increasing(knots: list[float], values: list[float]) -> tuple[list[float], list[float]]:
    """Drop knots that repeat an x (ties of raw confidence or of sigma), keeping the later (higher) value."""
    out_k, out_v = [], []
    for k, v in zip(knots, values):
        if out_k and k <= out_k[-1]:
            out_v[-1] = max(out_v[-1], v)
            continue
        out_k.append(float(k))
        out_v.append(float(v))
    return out_k, out_v


def reliability_table(confidence: np.ndarray, errors_deg: np.ndarray, *, tolerance_deg: float = 5.0,
                      bins: int = 10, order: np.ndarray | None = None) -> list[dict[str, float]]:
    """Per confidence bin (equal counts: deciles by default): confidence range, mean confidence, observed share
    within tolerance, median and p95 error, count.

    ``order`` (a permutation) bins the estimates in that order instead of by ``confidence``: the raw
    confidence's order puts the same estimates in each bin of a raw and a calibrated table (a calibration is
    flat below its first and above its last knot, where its own order would break ties otherwise).
    """
    conf = np.nan_to_num(np.asarray(confidence, float), nan=0.0)
    err = np.nan_to_num(np.abs(np.asarray(errors_deg, float)), nan=90.0)
    if conf.shape != err.shape or conf.ndim != 1 or conf.size < bins:
        raise ValueError(f"need matching 1-D confidences and errors, at least {bins}; got {conf.shape}, {err.shape}")
    order = np.argsort(conf, kind="stable") if order is None else np.asarray(order)
    rows = []
    for part in np.array_split(order, bins):
        c, e = conf[part], err[part]
        rows.append({"confidence_low": float(c.min()), "confidence_high": float(c.max()),
                     "mean_confidence": float(c.mean()), "within_tolerance": float(np.mean(e <= tolerance_deg)),
                     "median_error_deg": float(np.median(e)), "p95_error_deg": float(np.percentile(e, 95)),
                     "count": int(part.size)})
    return rows


def reliability_figure(rows: list[dict[str, float]], path: str | Path, *, title: str = "") -> Path:
    """Reliability diagram (observed share within tolerance against mean confidence per bin) and the error per
    bin, as a PNG."""
    from tactile_manip.plots import _pyplot

    plt = _pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.8), constrained_layout=True)
    mean_c = [r["mean_confidence"] for r in rows]
    a.plot([0, 1], [0, 1], color="0.6", linestyle="--", label="perfectly calibrated")
    a.plot(mean_c, [r["within_tolerance"] for r in rows], "o-", color="C0", label="observed")
    a.set_xlabel("confidence (bin mean)")
    a.set_ylabel("share within tolerance")
    a.set_xlim(0, 1)
    a.set_ylim(0, 1.02)
    a.legend(loc="upper left", fontsize=8)
    x = np.arange(1, len(rows) + 1)
    b.bar(x - 0.2, [r["median_error_deg"] for r in rows], width=0.4, label="median")
    b.bar(x + 0.2, [r["p95_error_deg"] for r in rows], width=0.4, label="p95")
    b.set_yscale("log")
    b.set_xlabel("confidence bin (1 = lowest)")
    b.set_ylabel("angle error [deg]")
    b.set_xticks(x)
    b.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)
