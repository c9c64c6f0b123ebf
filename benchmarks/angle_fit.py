"""Can a real estimator reach the angle bound? The simulator itself, fitted to each reading by maximum likelihood.

    python -m benchmarks.angle_fit --data data/rods_hard.npz --force 2 5      # the light presses of the hard protocol
    python -m benchmarks.angle_fit --data data/rods_hard.npz --limit 6 --workers 1   # a quick look
    python -m benchmarks.angle_fit --data data/rods_hard.npz --force 2 5 \
        --bound docs/results/angle_head/angle_information_rods_hard.json     # the bound's rows beside

The Cramer-Rao bound of ``benchmarks.angle_information`` is local: it says how well an efficient unbiased
estimator would do, and where the signal is weak no estimator need be efficient. This benchmark runs one that
has every advantage the bound grants: the physics that made the data. Each rod press of the dataset's test
split is read back through the same simulator (:meth:`~tactile_manip.sim.pair.SensorPair.expected_reading_ut`),
with the rod's kind and dimensions known, as for the bound "pose and sensor unknown". Fitted: the angle, the x
and y offsets, the force, the two tilts, the magnet's remanence and the chip gap, each inside the range the
dataset drew it from (the skin's modulus trades exactly against the force, so the force is fitted at the
nominal modulus over the range the two span). The residual is weighted by the press's own chip noise,
quantisation and drift, as in the bound, with saturated channels left out. The fit starts from the model's
angle head (and that angle turned by 90 and +-45 deg) at the centroid of the reading's z change; where the
best start still fits badly, from a grid of offsets as well.

Reported per force band and per object, beside the model's head on the same presses and, with ``--bound``,
the bound's shares. The likelihood at the true parameters is computed too: where it is higher than the fit's,
the optimiser stopped short of the maximum (counted as ``short``), so the fit's share is then a lower estimate
of what maximum likelihood reaches. ``--truth-start`` adds a start at the true parameters and reports the
likelier of the two answers as "ML": maximum likelihood itself, as well as local search can find it, which is
not an estimator one can run but says whether the bound is within reach of one. About 10-20 s per press on
one core. Prints markdown and writes docs/results/benchmarks/angle_fit.json; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from benchmarks.angle_information import FORCE_BANDS_N, _jobs, rod_presses, white_var
from tactile_manip.data import load_dataset

FITTED = ("angle_deg", "x_mm", "y_mm", "log_force_n", "tilt_x_deg", "tilt_y_deg", "remanence_mt", "chip_gap_mm")
STEPS = np.array([0.5, 0.05, 0.05, 0.01, 0.25, 0.25, 0.25, 0.01])  # forward-difference steps, in FITTED units
FIRST = [0, 1, 2, 3]          # the first stage fits the angle, offsets and force; the second all of FITTED
TURNS_DEG = (0.0, 90.0, 45.0, -45.0)
GRID_MM = (-2.0, 2.0)         # offsets of the retry grid
RETRY_CHI2 = 1.5              # a fit whose chi-square per channel is above this is retried from the grid
MAX_EVALS = 40                # residual evaluations per least-squares run


def fit_box(config: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, float]:
    """Lower and upper bounds of FITTED from the dataset's pose ranges and the simulator's sensor ranges, and
    the nominal skin modulus (kPa) at which the force is fitted."""
    from tactile_manip.boards import load_board
    from tactile_manip.sim.params import describe, for_board

    poses = config.get("poses", {})
    offset, tilt = float(poses.get("offset_mm", 5.0)), float(poses.get("tilt_deg", 2.0))
    f_lo, f_hi = map(float, poses.get("force_n", (10.0, 11.0)))
    nominal = for_board(load_board("supermag-4x4"))
    ranges = {row["name"]: (row["value"], row["rand"]) for row in describe(nominal)}
    spread = float(config.get("randomise_spread", 0.0))

    def span(name: str) -> tuple[float, float, float]:
        value, rand = ranges[name]
        if rand is None:
            return value, value, value
        lo, hi = value + spread * (rand[0] - value), value + spread * (rand[1] - value)
        return value, min(lo, hi), max(lo, hi)

    e_nom, e_lo, e_hi = span("layer.skin_modulus_kpa")
    _, r_lo, r_hi = span("magnet.remanence_t")
    _, g_lo, g_hi = span("magnet.chip_gap_mm")
    lo = np.array([-np.inf, -offset, -offset, math.log(f_lo * e_nom / e_hi), -tilt, -tilt, r_lo * 1e3, g_lo])
    hi = np.array([np.inf, offset, offset, math.log(f_hi * e_nom / e_lo), tilt, tilt, r_hi * 1e3, g_hi])
    hi = np.where(hi > lo, hi, lo + STEPS)  # a range the dataset did not draw: a sliver around its value
    return lo, hi, e_nom


class _Press:
    """One recorded press and the simulator that reads a parameter vector (FITTED) into its expected reading."""

    def __init__(self, job: dict[str, Any], reading: np.ndarray, lo: np.ndarray, hi: np.ndarray, e_nom: float):
        from tactile_manip.boards import load_board
        from tactile_manip.sim.params import for_board, with_values
        from tactile_manip.sim.shapes import make_indenter

        self.params = for_board(load_board("supermag-4x4"))
        if job["params"] is not None:
            self.params = with_values(self.params, job["params"])
        self.params = with_values(self.params, {"layer.skin_modulus_kpa": e_nom})
        c = self.params.chip
        var = white_var(c) + c.drift_ut ** 2
        self.sigma, self.keep = np.sqrt(var), ~np.asarray(job["saturated"], bool).ravel()
        self.reading = reading.ravel().astype(np.float64)
        self.rod, self.seed = make_indenter(job["kind"], **job["kwargs"]), job["sensor_seed"]
        self.lo, self.hi = lo, hi
        self.pairs: dict[tuple[float, float], Any] = {}
        self.evaluations = 0

    def pair(self, remanence_mt: float, gap_mm: float) -> Any:
        from tactile_manip.sim.pair import SensorPair
        from tactile_manip.sim.params import with_values

        key = (round(remanence_mt, 9), round(gap_mm, 9))
        if key not in self.pairs:
            values = {"magnet.remanence_t": remanence_mt * 1e-3, "magnet.chip_gap_mm": gap_mm}
            self.pairs[key] = SensorPair(with_values(self.params, values), seed=self.seed)
        return self.pairs[key]

    def residual(self, t: np.ndarray) -> np.ndarray:
        from tactile_manip.errors import SimulationError
        from tactile_manip.sim.objects import IndenterPose

        self.evaluations += 1
        pose = IndenterPose(t[1], t[2], math.radians(t[0]), math.radians(t[4]), math.radians(t[5]))
        try:
            expected = self.pair(t[6], t[7]).expected_reading_ut(self.rod, pose, math.exp(t[3])).ravel()
        except SimulationError:  # a contact the solver cannot settle: as unlikely as a reading can be
            return np.full(int(self.keep.sum()), 1e3)
        return ((self.reading - expected) / self.sigma)[self.keep]

    def fit(self, start: np.ndarray, free: list[int]) -> tuple[np.ndarray, float]:
        """Least squares over the ``free`` entries of FITTED from ``start``: the parameters and half the
        chi-square (the negative log-likelihood up to a constant)."""
        from scipy.optimize import least_squares

        def full(z: np.ndarray) -> np.ndarray:
            t = start.copy()
            t[free] = z
            return t

        def jacobian(z: np.ndarray) -> np.ndarray:
            t, cols = full(z), []
            r0 = self.residual(t)
            for k in free:
                step = STEPS[k] if t[k] + STEPS[k] <= self.hi[k] else -STEPS[k]
                e = np.zeros(len(t))
                e[k] = step
                cols.append((self.residual(t + e) - r0) / step)
            return np.stack(cols, 1)

        lo, hi = self.lo[free], self.hi[free]
        z0 = np.clip(start[free], lo + 1e-6, hi - 1e-6)
        r = least_squares(lambda z: self.residual(full(z)), z0, jac=jacobian, bounds=(lo, hi), method="trf",
                          x_scale=STEPS[free] * 10, max_nfev=MAX_EVALS, xtol=1e-4, ftol=1e-6)
        return full(r.x), float(r.cost)


def z_centroid_mm(reading: np.ndarray, chips_mm: np.ndarray) -> tuple[float, float]:
    """The chips' positions weighted by the magnitude of the reading's z change: a start for the offsets."""
    w = np.abs(np.asarray(reading, float).reshape(16, 3)[:, 2])
    if w.sum() <= 0:
        return 0.0, 0.0
    return float(w @ chips_mm[:, 0] / w.sum()), float(w @ chips_mm[:, 1] / w.sum())


def fit_press(job: dict[str, Any]) -> dict[str, Any]:
    """The maximum-likelihood fit of one press (``job``: an angle_information job plus the reading, the head's
    angle, the fit's box and the truth in FITTED units)."""
    start_s = time.perf_counter()
    lo, hi = np.asarray(job["lo"]), np.asarray(job["hi"])
    press = _Press(job, np.asarray(job["reading"]), lo, hi, job["e_nom"])
    nominal = press.pair(*[0.5 * (lo[k] + hi[k]) for k in (6, 7)])
    x0, y0 = z_centroid_mm(job["reading"], nominal.skin.chips_mm)
    centre = np.array([job["head_deg"], x0, y0, 0.5 * (lo[3] + hi[3]), 0.0, 0.0, 0.5 * (lo[6] + hi[6]),
                       0.5 * (lo[7] + hi[7])])

    def best_of(starts: list[np.ndarray]) -> tuple[np.ndarray, float]:
        first = min((press.fit(s, FIRST) for s in starts), key=lambda f: f[1])
        return press.fit(first[0], list(range(len(FITTED))))

    earlier = job.get("earlier")
    if earlier is not None:  # this press's fit from an earlier run of the same presses (--reuse)
        theta = np.array([earlier["fitted"][name] for name in FITTED])
        cost, retried = earlier["cost"], earlier["retried"]
    else:
        turned = [centre + np.eye(len(FITTED))[0] * turn for turn in TURNS_DEG]
        theta, cost = best_of(turned)
        retried = 2 * cost / press.keep.sum() > RETRY_CHI2
        if retried:
            grid = [np.concatenate([[s[0], dx, dy], s[3:]]) for s in turned for dx in GRID_MM for dy in GRID_MM]
            theta, cost = min([(theta, cost), best_of(grid)], key=lambda f: f[1])
    truth = np.clip(np.asarray(job["truth"]), lo, hi)
    truth_cost = 0.5 * float(np.sum(press.residual(truth) ** 2))
    extra = {}
    if job.get("truth_start"):  # the likelihood's maximum as well as starts can find it, the truth among them
        at_truth, cost_truth_start = press.fit(truth, list(range(len(FITTED))))
        best = at_truth if cost_truth_start < cost else theta
        extra = {"ml_error_deg": axial_error_deg(best[0], job["truth"][0]), "ml_from_truth": cost_truth_start < cost}
    return {"index": job["index"], "label": job["label"], "force_n": job["force_n"], **extra,
            "fit_error_deg": axial_error_deg(theta[0], job["truth"][0]),
            "head_error_deg": axial_error_deg(job["head_deg"], job["truth"][0]),
            "cost": cost, "chi2_per_channel": 2 * cost / int(press.keep.sum()), "short": truth_cost < cost - 1e-6,
            "retried": bool(retried), "fitted": dict(zip(FITTED, map(float, theta))),
            "evaluations": press.evaluations, "seconds": time.perf_counter() - start_s}


def axial_error_deg(a_deg: float, b_deg: float) -> float:
    """|a - b| as axes (modulo 180 deg), in [0, 90]."""
    from tactile_manip.perception import wrap_axial

    return float(abs(math.degrees(wrap_axial(math.radians(a_deg - b_deg)))))


def head_angles_deg(model: str, readings: np.ndarray) -> np.ndarray:
    """The angle the model's default route gives each reading (deg)."""
    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor

    est = TactilePoseEstimator(load_reconstructor(model, threads=1))
    out = [e.angle_rad for s in range(0, len(readings), 256)
           for e in est.estimate_many(list(readings[s:s + 256].astype(np.float64)))]
    return np.degrees(out)


def groups(rows: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    """The rows of each reported group (all, each force band, each object) as masks; empty groups left out."""
    force = np.array([r["force_n"] for r in rows])
    labels = np.array([r["label"] for r in rows])
    out = {"all": np.ones(len(rows), bool)}
    out |= {f"{lo:g}-{hi:g} N": (force >= lo) & (force < hi) for lo, hi in FORCE_BANDS_N}
    out |= {str(name): labels == name for name in sorted(set(labels.tolist()))}
    return {name: sel for name, sel in out.items() if sel.any()}


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    fit = np.array([r["fit_error_deg"] for r in rows])
    head = np.array([r["head_error_deg"] for r in rows])
    short = np.array([r["short"] for r in rows])
    ml = np.array([r["ml_error_deg"] for r in rows]) if rows and all("ml_error_deg" in r for r in rows) else None
    out = {}
    for name, sel in groups(rows).items():
        out[name] = {"presses": int(sel.sum()), "fit_within_5": float(np.mean(fit[sel] <= 5)),
                     "head_within_5": float(np.mean(head[sel] <= 5)),
                     "fit_median_deg": float(np.median(fit[sel])), "head_median_deg": float(np.median(head[sel])),
                     "fit_only": int(np.sum((fit[sel] <= 5) & (head[sel] > 5))),
                     "head_only": int(np.sum((head[sel] <= 5) & (fit[sel] > 5))),
                     "short": int(short[sel].sum()), "short_and_missed": int(np.sum(short[sel] & (fit[sel] > 5)))}
        if ml is not None:
            out[name]["ml_within_5"] = float(np.mean(ml[sel] <= 5))
    return out


def markdown(report: dict[str, Any]) -> str:
    bound = report.get("bound", {})
    ml = all("ml_within_5" in row for row in report["summary"].values())
    lines = [f"Maximum-likelihood fit of the simulator to each of {report['presses']} rod presses of "
             f"{report['source']} ({report['seconds']:.0f} s, {report['workers']} workers): the rod's shape known; "
             "pose, force, remanence and chip gap fitted. Within 5 deg, beside the model's head on the same presses"
             + (" and the Cramer-Rao bound (pose and sensor unknown)." if bound else ".")
             + (" ML: the likelier of the fit and a fit started at the true parameters, what maximum likelihood "
                "itself reaches (not an estimator one can run)." if ml else ""), "",
             "| presses | n | fit | " + ("ML | " if ml else "") + "head | " + ("bound | " if bound else "")
             + "fit only / head only | fit median / head median deg | optimiser short (of which missed) |",
             "|---|---|---|" + ("---|" if ml else "") + "---|" + ("---|" if bound else "") + "---|---|---|"]
    for name, row in report["summary"].items():
        b = f"{bound[name]:.1%} | " if bound else ""
        if bound and name not in bound:
            b = "- | "
        m = f"{row['ml_within_5']:.1%} | " if ml else ""
        lines.append(f"| {name} | {row['presses']} | {row['fit_within_5']:.1%} | {m}{row['head_within_5']:.1%} | {b}"
                     f"{row['fit_only']} / {row['head_only']} | {row['fit_median_deg']:.2f} / "
                     f"{row['head_median_deg']:.2f} | {row['short']} ({row['short_and_missed']}) |")
    lines += ["", "\"Optimiser short\": presses where the true parameters are likelier than the fit's, so the "
              "maximum lies elsewhere; where such a press is also missed, maximum likelihood itself may not miss it."]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="data/rods_hard.npz")
    parser.add_argument("--split", default="test")
    parser.add_argument("--force", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                        help="only presses with LOW <= force < HIGH, N")
    parser.add_argument("--limit", type=int, default=0, help="the first N rod presses only (0: all)")
    parser.add_argument("--workers", type=int, default=0, help="processes (0: all cores)")
    parser.add_argument("--model", default=None, help="model whose angle starts the fit (default: the shipped one)")
    parser.add_argument("--bound", default=None, help="angle_information JSON of the same dataset")
    parser.add_argument("--truth-start", action="store_true",
                        help="also start each fit at the true parameters: what maximum likelihood itself reaches")
    parser.add_argument("--reuse", default=None, metavar="REPORT.json",
                        help="take each press's fit from an earlier report of the same presses (with --truth-start: "
                             "only the fits started at the truth are run)")
    parser.add_argument("--out", default="docs/results/benchmarks/angle_fit.json")
    args = parser.parse_args()
    if args.force is not None and not 0 <= args.force[0] < args.force[1]:
        parser.error(f"--force needs 0 <= LOW < HIGH, got {args.force}")
    publish(compute(args), args.out, markdown)


def compute(args: argparse.Namespace) -> dict[str, Any]:
    from tactile_manip.shipped import shipped_model

    data = load_dataset(args.data)
    idx, specs = rod_presses(data, args.split)
    force, pose = data.extra("force_n"), data.extra("pose")
    if args.force is not None:
        idx = idx[(force[idx] >= args.force[0]) & (force[idx] < args.force[1])]
    if args.limit:
        idx = idx[:args.limit]
    if not idx.size:
        raise SystemExit(f"{args.data}: no rod press of the {args.split} split in that force range")
    config = data.provenance["config"]
    lo, hi, e_nom = fit_box(config)
    model = args.model or str(shipped_model())
    heads = head_angles_deg(model, data.readings[idx])
    names = data.provenance.get("sensor_param_names")
    drawn = data.extra("sensor_params") if data.has("sensor_params") else None
    jobs = []
    for job, head in zip(_jobs(data, idx, specs), heads):
        i = job["index"]
        values = dict(zip(names, map(float, drawn[i]))) if drawn is not None else {}
        modulus = values.get("layer.skin_modulus_kpa", e_nom)
        truth = [math.degrees(pose[i, 2]), pose[i, 0], pose[i, 1], math.log(force[i] * e_nom / modulus),
                 math.degrees(pose[i, 3]), math.degrees(pose[i, 4]),
                 values.get("magnet.remanence_t", 0.5 * (lo[6] + hi[6]) * 1e-3) * 1e3,
                 values.get("magnet.chip_gap_mm", 0.5 * (lo[7] + hi[7]))]
        jobs.append(job | {"reading": data.readings[i].tolist(), "head_deg": float(head), "lo": lo.tolist(),
                           "hi": hi.tolist(), "e_nom": e_nom, "truth": [float(v) for v in truth],
                           "truth_start": args.truth_start})
    from tqdm import tqdm

    if args.reuse:
        earlier = {row["index"]: row for row in json.loads(Path(args.reuse).read_text())["per_press"]}
        missing = [j["index"] for j in jobs if j["index"] not in earlier]
        if missing:
            raise SystemExit(f"--reuse {args.reuse} has no fit of press {missing[0]} ({len(missing)} missing)")
        for j in jobs:
            row = earlier[j["index"]]
            keep = int(np.sum(~np.asarray(j["saturated"], bool)))
            j["earlier"] = {"fitted": row["fitted"], "retried": row["retried"],
                            "cost": row.get("cost", row["chi2_per_channel"] * keep / 2)}
    start = time.perf_counter()
    workers = args.workers or os.cpu_count() or 1
    rows: list[dict[str, Any]] = []
    with ExitStack() as stack:
        bar = stack.enter_context(tqdm(total=len(jobs), unit="press", desc="fitting"))
        if workers == 1:
            results = map(fit_press, jobs)
        else:
            pool = stack.enter_context(ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")))
            results = pool.map(fit_press, jobs, chunksize=1)
        for row in results:
            rows.append(row)
            bar.update(1)
    report = {"machine": machine_info(), "source": f"{args.data} {args.split} split", "presses": len(rows),
              "force_n": args.force, "model": model, "workers": workers, "seconds": time.perf_counter() - start,
              "fitted": FITTED, "box": {"low": lo.tolist(), "high": hi.tolist()}, "nominal_modulus_kpa": e_nom,
              "summary": summarise(rows), "per_press": rows}
    if args.bound:
        bound = json.loads(Path(args.bound).read_text())
        shares = {p["index"]: p["pose_sensor_sigma_deg"] for p in bound["per_press"]}
        report["bound"] = _bound_shares(rows, shares)
    return report


def _bound_shares(rows: list[dict[str, Any]], sigma_deg: dict[int, float]) -> dict[str, float]:
    """The bound's share within 5 deg over the same presses as each row of the summary."""
    from benchmarks.angle_information import within

    missing = [r["index"] for r in rows if r["index"] not in sigma_deg]
    if missing:
        raise SystemExit(f"--bound has no press {missing[0]} of these ({len(missing)} missing): another dataset?")
    sigma = np.array([sigma_deg[r["index"]] for r in rows])
    return {name: within(sigma[sel], 5.0) for name, sel in groups(rows).items()}


if __name__ == "__main__":
    main()
