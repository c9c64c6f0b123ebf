"""``tactile-manip calibrate``: fit a model's confidence to the probability its angle is within tolerance.

Runs the estimator (one pass per reading by default; ``--samples K`` and ``--symmetrized`` calibrate those
estimators instead) on the rod presses of ``--fit`` (held-out presses: ``configs/dataset/calibration.toml``
holds rods of sizes used neither in training nor in the tests), fits
:class:`~tactile_manip.perception.confidence.ConfidenceCalibration` (isotonic) on "angle error <= tolerance",
and checks it on the rod presses of ``--report`` (other presses: unseen shapes), giving the error per confidence
decile before and after calibration and a reliability plot. Writes the calibration (``--out``, by default
beside the model as ``<model>.calibration.json``, where the trials find it), and beside it
``<name>.reliability.md``, ``.json`` and ``.png``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

MAX_TOLERANCE_DEG = 90.0
MIN_FIT_PRESSES = 40   # two isotonic blocks of 20 at least
REPORT_BINS = 10       # confidence deciles in the report


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", required=True, help="an exported .onnx model (or 'bilinear' / 'bicubic')")
    p.add_argument("--fit", required=True, metavar="DATA", help="paired dataset whose rod presses fit the calibration")
    p.add_argument("--fit-split", default="test", choices=("train", "val", "test"),
                   help="split of --fit to use (default test: configs/dataset/calibration.toml puts its rods there)")
    p.add_argument("--report", required=True, metavar="DATA",
                   help="paired dataset whose rod presses check the calibration (other presses than --fit's)")
    p.add_argument("--report-split", default="test", choices=("train", "val", "test"),
                   help="the split of --report whose presses check the fitted calibration (default test)")
    p.add_argument("--tolerance-deg", type=float, default=5.0, help="the error the probability is about (default 5)")
    p.add_argument("--samples", type=int, default=1,
                   help="ONNX models: prior samples per reading, as the estimator will run (default 1: one pass)")
    p.add_argument("--symmetrized", action="store_true",
                   help="calibrate the model averaged over the sensor's symmetries (SymmetrizedReconstructor)")
    p.add_argument("--out", default=None, help="calibration JSON (default: beside the model)")
    p.add_argument("--force", action="store_true", help="replace an earlier calibration and its report")


def run(args: argparse.Namespace) -> int:
    import json

    import numpy as np

    from tactile_manip.data import check_dataset_file, load_dataset
    from tactile_manip.errors import ConfigError
    from tactile_manip.extras import require
    from tactile_manip.outputs import check_output_file
    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
    from tactile_manip.perception.confidence import (ConfidenceCalibration, calibration_path, reliability_figure,
                                                     reliability_table)
    from tactile_manip.perception.symmetry import SymmetrizedReconstructor
    from tactile_manip.shipped import resolve_model_path

    tol = args.tolerance_deg
    if not (math.isfinite(tol) and 0.0 < tol <= MAX_TOLERANCE_DEG):
        raise ConfigError(f"--tolerance-deg must be in (0, {MAX_TOLERANCE_DEG:g}] deg, got {tol}")
    baseline = args.model in ("bilinear", "bicubic")
    if args.samples < 1 or (baseline and args.samples != 1):
        raise ConfigError(f"--samples must be >= 1, and 1 for a baseline; got {args.samples} for {args.model}")
    require("sklearn.isotonic", "fitting a calibration")   # before any inference or file
    # beside the model file (a shipped model's name, or a checkout path run from another folder, found first)
    out = Path(args.out) if args.out else calibration_path(args.model if baseline else resolve_model_path(args.model))
    stem = out.with_suffix("")
    report_files = [out] + [Path(f"{stem}.reliability.{ext}") for ext in ("md", "json", "png")]
    for path in report_files:
        check_output_file(path, force=args.force)
    out.parent.mkdir(parents=True, exist_ok=True)
    for path in (args.fit, args.report):
        check_dataset_file(path)
    # the images as the model file says (the trials' estimators decode them so)
    reconstructor = load_reconstructor(args.model, **({} if baseline else {"samples": args.samples,
                                                                          "image_symmetry": "stored"}))
    if args.symmetrized:
        reconstructor = SymmetrizedReconstructor(reconstructor)
    # the image's confidence alone: the estimator maps it before weighing a model's angle head against it
    estimator = TactilePoseEstimator(reconstructor)  # the route the estimator takes by default (its angle head)
    fit = load_dataset(args.fit)
    fit.require_images(f"calibrate --fit {args.fit}")
    _, fit_conf, fit_err = _rods(fit, "--fit", args.fit, args.fit_split, estimator)
    if fit_conf.size < MIN_FIT_PRESSES:
        raise ConfigError(f"--fit {args.fit} has {fit_conf.size} rod presses in split {args.fit_split!r}; "
                          f"calibrating needs >= {MIN_FIT_PRESSES}")
    cal = ConfidenceCalibration.fit(fit_conf, fit_err, tolerance_deg=tol, prior_samples=args.samples,
                                    symmetrized=args.symmetrized, aperture=estimator.params.aperture,
                                    route=estimator.angle_source)
    report = load_dataset(args.report)
    report.require_images(f"calibrate --report {args.report}")
    _, raw, err = _rods(report, "--report", args.report, args.report_split, estimator)
    if raw.size < REPORT_BINS:
        raise ConfigError(f"--report {args.report} has {raw.size} rod presses in split {args.report_split!r}; "
                          f"the decile table needs >= {REPORT_BINS}")
    order = np.argsort(raw, kind="stable")  # the same presses in each decile before and after
    before = reliability_table(raw, err, tolerance_deg=tol, bins=REPORT_BINS, order=order)
    after = reliability_table(cal(raw), err, tolerance_deg=tol, bins=REPORT_BINS, order=order)
    cal.save(out)
    summary = {"model": str(args.model), "tolerance_deg": tol, "samples": args.samples, "route": estimator.angle_source,
               "symmetrized": args.symmetrized,
               "fit": {"data": str(args.fit), "split": args.fit_split, "presses": int(fit_conf.size),
                       "within_tolerance": float(np.mean(fit_err <= tol))},
               "report": {"data": str(args.report), "split": args.report_split, "presses": int(raw.size),
                          "within_tolerance": float(np.mean(err <= tol)),
                          "expected_calibration_error": _ece(after), "expected_calibration_error_raw": _ece(before)},
               "deciles_raw": before, "deciles_calibrated": after, "calibration": cal.to_dict()}
    report_files[2].write_text(json.dumps(summary, indent=1))
    report_files[1].write_text(_markdown(summary))
    reliability_figure(after, report_files[3], title=f"{Path(args.model).name}: calibrated confidence on "
                                                     f"{raw.size} held-out rod presses (|error| <= {tol:g} deg)")
    print(_markdown(summary))
    print(f"wrote {out} and {stem}.reliability.{{md,json,png}}")
    return 0


def _rods(data, option: str, path: str, split: str, estimator):
    """:func:`~tactile_manip.evaluation.images.rod_estimates` on ``split`` of ``data``, its errors naming the
    option, file and split."""
    from tactile_manip.errors import ConfigError
    from tactile_manip.evaluation.images import rod_estimates

    try:
        return rod_estimates(data, data.indices(split), estimator)
    except ValueError as e:
        raise ConfigError(f"{option} {path}, split {split!r}: {e}") from e


def _ece(rows: list[dict]) -> float:
    """Expected calibration error: the count-weighted mean |observed share - mean confidence| over the bins."""
    n = sum(r["count"] for r in rows)
    return float(sum(r["count"] * abs(r["within_tolerance"] - r["mean_confidence"]) for r in rows) / n)


def _markdown(s: dict) -> str:
    r, f = s["report"], s["fit"]
    how = f"{s['samples']} sample(s) per reading" + (", symmetry-averaged" if s["symmetrized"] else "")
    lines = [f"Confidence calibration of {s['model']} (P(|angle error| <= {s['tolerance_deg']:g} deg), {how})", "",
             f"- fitted on {f['presses']} rod presses of {f['data']} ({f['split']}): "
             f"{100 * f['within_tolerance']:.1f} % within tolerance",
             f"- checked on {r['presses']} rod presses of {r['data']} ({r['split']}): "
             f"{100 * r['within_tolerance']:.1f} % within tolerance; expected calibration error "
             f"{r['expected_calibration_error']:.3f} (raw confidence: {r['expected_calibration_error_raw']:.3f})", "",
             "| decile | raw confidence | calibrated (mean) | observed within tol. | median err. deg | p95 err. deg | n |",
             "|---|---|---|---|---|---|---|"]
    for i, (a, b) in enumerate(zip(s["deciles_raw"], s["deciles_calibrated"]), start=1):
        lines.append(f"| {i} | {a['confidence_low']:.3f}-{a['confidence_high']:.3f} | {b['mean_confidence']:.3f} | "
                     f"{b['within_tolerance']:.3f} | {b['median_error_deg']:.2f} | {b['p95_error_deg']:.1f} | "
                     f"{b['count']} |")
    return "\n".join(lines) + "\n"
