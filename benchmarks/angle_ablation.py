"""What each route to a bar's angle buys, per force band and per bar, on single frames of unseen bars.

    python -m benchmarks.angle_ablation --data data/rods_test.npz \\
        --model fast=experiments/model_variants/supermag_fast.onnx \\
        --model robust=experiments/model_variants/supermag_robust.onnx \\
        --model default=models/supermag.onnx --bound docs/results/benchmarks/angle_information_rods_test.json

For every ``--model`` the presses of elongated objects in the dataset's test split (rods and flat bars; single
frames, as recorded) go through :class:`~tactile_manip.perception.TactilePoseEstimator`: the image route alone
(the principal axis of the reconstruction), and, for a model file with an angle head, the estimator's default
(the head's angle, its confidence calibrated), the head's raw output, and "likelier", whichever of image and
head is the more likely within 5 deg (the image's probability from the calibration of the same image graphs,
``experiments/model_variants/supermag_robust.calibration.json``). Beside them: the principal axis of the true
(simulated) depth image, what the image route would get from a perfect reconstruction, and with ``--bound`` (the JSON of ``benchmarks.angle_information`` on the
same dataset) the share an efficient estimator would reach per band (Cramer-Rao, pose and sensor unknown).
Reported: share within 5 and 2 deg, median error, within 5 deg per force band and per object; and the head's
reliability (the probability its concentration gives against the share observed). With ``--draws N`` the
head also reads every press through N fresh draws of its chips (the stored clean field, new noise): once with
drift as recorded presses carry it, once tared (no drift, as after a baseline taken just before the press),
each the mean over the draws with the lowest and highest draw's share. ``--model NAME=A.onnx,B.onnx`` reads the
angle heads of several files as one (the mean of their doubled-angle vectors; an ensemble of heads of other
seeds): its raw output and, with ``--draws``, its fresh draws. Prints markdown, writes
docs/results/benchmarks/angle_ablation.json; asserts nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.data import load_dataset
from tactile_manip.evaluation.images import ELONGATED
from tactile_manip.perception import (
    TactilePoseEstimator,
    load_reconstructor,
    wrap_axial,
)
from tactile_manip.perception.angle_head import within_probability
from tactile_manip.perception.confidence import load_calibration_beside
from tactile_manip.perception.pose import angle_from_image

REFERENCES = Path(__file__).resolve().parents[1] / "experiments" / "model_variants"  # the reference models
FORCE_BANDS_N = ((2.0, 5.0), (5.0, 8.0), (8.0, 11.0), (11.0, 15.0))
RELIABILITY_BINS = ((0.0, 0.5), (0.5, 0.8), (0.8, 0.95), (0.95, 1.0001))


def errors_deg(angle_rad: np.ndarray, defined: np.ndarray, yaw_rad: np.ndarray) -> np.ndarray:
    """|axial error| in deg, 90 where undefined."""
    return np.where(defined, np.degrees(np.abs(wrap_axial(angle_rad - yaw_rad))), 90.0)


def summary(err: np.ndarray, force: np.ndarray, names: np.ndarray) -> dict[str, Any]:
    row = {"presses": int(err.size), "within_5": float(np.mean(err <= 5)), "within_2": float(np.mean(err <= 2)),
           "median_deg": float(np.median(err)), "by_force": {}, "by_object": {}}
    for lo, hi in FORCE_BANDS_N:
        sel = (force >= lo) & (force < hi) if hi < FORCE_BANDS_N[-1][1] else (force >= lo) & (force <= hi)
        if sel.any():
            row["by_force"][f"{lo:g}-{hi:g} N"] = float(np.mean(err[sel] <= 5))
    for name in sorted(set(names.tolist())):
        row["by_object"][name] = float(np.mean(err[names == name] <= 5))
    return row


def route_estimates(path: str, readings: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(angle, defined, probability-or-confidence) per route of one model file on ``readings`` (N, R, C, A)."""
    model = load_reconstructor(path, threads=2)
    calibration = load_calibration_beside(path)
    routes = {"image": TactilePoseEstimator(model, angle_source="image")}
    if model.angle_head is not None:
        routes["head (the default)"] = TactilePoseEstimator(
            model, calibration=calibration if calibration is not None and calibration.route == "head" else None)
        image_cal = load_calibration_beside(REFERENCES / "supermag_robust.onnx")  # the same image graphs, fitted on their angles
        if image_cal is not None:  # the image's probability is its calibrated confidence
            routes["likelier of image and head"] = TactilePoseEstimator(
                model, calibration=dataclasses.replace(image_cal, route="likelier"), angle_source="likelier")
    out = {}
    for name, est in routes.items():
        ests = [e for s in range(0, len(readings), 256)
                for e in est.estimate_many(list(readings[s:s + 256].astype(np.float64)))]
        out[name] = (np.array([e.angle_rad for e in ests]), np.array([e.defined for e in ests]),
                     np.array([e.confidence for e in ests]))
    if model.angle_head is not None:
        angle, kappa = model.angle_head.axes(np.stack([model.checked(r) for r in readings]))
        out["head, raw probability"] = (angle, np.ones(len(angle), bool),
                                            within_probability(kappa, math.radians(5.0)))
    return out


def head_axes(paths: Sequence[str]) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None:
    """The angle heads of the model files at ``paths`` read as one: each reading's axis is that of the mean of the
    heads' doubled-angle vectors kappa (cos 2t, sin 2t), its concentration that mean's length (the heads' own
    where they agree, less where they do not). None where a file has no head."""
    models = [load_reconstructor(path, threads=2) for path in paths]
    if any(model.angle_head is None for model in models):
        return None

    def axes(readings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if len(models) == 1:
            return models[0].angle_head.axes(np.stack([models[0].checked(r) for r in readings]))
        total = np.zeros((len(readings), 2))
        for model in models:
            angle, kappa = model.angle_head.axes(np.stack([model.checked(r) for r in readings]))
            total += kappa[:, None] * np.stack([np.cos(2 * angle), np.sin(2 * angle)], axis=1)
        total /= len(models)
        return 0.5 * np.arctan2(total[:, 1], total[:, 0]), np.hypot(total[:, 0], total[:, 1])
    return axes


def fresh_draws(axes: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], model: str, data, idx: np.ndarray,
                draws: int, yaw: np.ndarray, force: np.ndarray, names: np.ndarray) -> dict[str, dict[str, Any]]:
    """The head ``axes`` (:func:`head_axes`) of ``model`` on ``draws`` fresh readings of every press (its stored
    clean field through new chip noise, :class:`~tactile_manip.learning.noise.ChipNoise`), with the drift as
    recorded presses have it and without (a baseline taken just before the press): each summary is the mean over
    the draws, with the lowest and highest share within 5 deg, overall and at 2-5 N."""
    from tactile_manip.learning.noise import ChipNoise

    chips = ChipNoise.of(data, idx, data.provenance)
    cases = {f"fresh chip draws (mean of {draws})": chips,
             f"fresh chip draws, tared (mean of {draws})": dataclasses.replace(chips,
                                                                              drift_ut=np.zeros_like(chips.drift_ut))}
    out = {}
    for seed, (case, noise) in enumerate(cases.items()):
        rng = np.random.default_rng(seed)  # the same draws for every model
        rows = []
        for _ in range(draws):
            angle, _kappa = axes(noise.draw(rng))
            rows.append(summary(errors_deg(angle, np.ones(len(angle), bool), yaw), force, names))
        mean = {k: float(np.mean([r[k] for r in rows])) for k in ("within_5", "within_2", "median_deg")}
        for part in ("by_force", "by_object"):
            mean[part] = {k: float(np.mean([r[part][k] for r in rows])) for k in rows[0][part]}
        light = [r["by_force"].get("2-5 N", math.nan) for r in rows]
        out[case] = {"presses": rows[0]["presses"], **mean, "model": model, "reliability": [], "draws": draws,
                     "within_5_range": [min(r["within_5"] for r in rows), max(r["within_5"] for r in rows)],
                     "within_5_at_2_5_n_range": [min(light), max(light)]}
    return out


def reliability(prob: np.ndarray, err: np.ndarray) -> list[dict[str, float]]:
    rows = []
    for lo, hi in RELIABILITY_BINS:
        sel = (prob >= lo) & (prob < hi)
        if sel.any():
            rows.append({"bin": f"{lo:g}-{min(hi, 1):g}", "presses": int(sel.sum()),
                         "predicted": float(prob[sel].mean()), "observed": float(np.mean(err[sel] <= 5))})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="data/rods_test.npz")
    parser.add_argument("--model", action="append", default=[], metavar="NAME=PATH[,PATH...]", required=True,
                        help="a model file; several, comma-separated, read their angle heads as one (the mean of "
                             "their doubled-angle vectors): the heads' raw output only")
    parser.add_argument("--bound", default=None, help="angle_information JSON of the same dataset")
    parser.add_argument("--out", default="docs/results/benchmarks/angle_ablation.json")
    parser.add_argument("--draws", type=int, default=0, metavar="N",
                        help="also read each press through N fresh draws of its chips' noise, with drift and "
                             "tared (drift removed): the head's spread over draws and what a tare buys")
    args = parser.parse_args()
    if args.draws < 0:
        parser.error(f"--draws must be >= 0, got {args.draws}")
    data = load_dataset(args.data)
    idx = data.indices("test")
    idx = idx[[any(str(n).startswith(e) for e in ELONGATED) for n in data.objects(idx)]]
    yaw, force, names = data.extra("pose")[idx, 2], data.extra("force_n")[idx], data.objects(idx)
    readings = data.readings[idx]
    results: dict[str, Any] = {}
    for spec in args.model:
        label, _, path = spec.partition("=")
        paths = path.split(",")
        axes = head_axes(paths) if len(paths) > 1 or args.draws else None
        if len(paths) == 1:
            estimates = route_estimates(path, readings)
        else:  # several heads read as one: their raw output only
            if axes is None:
                parser.error(f"--model {spec}: every file of an ensemble needs an angle head")
            angle, kappa = axes(readings)
            estimates = {"head, raw probability": (angle, np.ones(len(angle), bool),
                                                   within_probability(kappa, math.radians(5.0)))}
        for route, (angle, defined, prob) in estimates.items():
            err = errors_deg(angle, defined, yaw)
            results[f"{label}: {route}"] = {**summary(err, force, names), "model": path,
                                            "reliability": reliability(prob, err) if route.startswith("head") else []}
        if args.draws and axes is not None:
            results |= {f"{label}: head, {case}": row for case, row in
                        fresh_draws(axes, path, data, idx, args.draws, yaw, force, names).items()}
    if data.has_images:
        truth = [angle_from_image(img, pixel_mm=data.image.pixel_mm) for img in data.depth_mm(idx)]
        err = errors_deg(np.array([t.angle_rad for t in truth]), np.array([t.defined for t in truth]), yaw)
        results["principal axis of the true image"] = summary(err, force, names)
    report = {"machine": machine_info(), "data": args.data, "presses": int(idx.size), "results": results}
    if args.bound:
        import json
        from pathlib import Path

        bound = json.loads(Path(args.bound).read_text())
        report["bound"] = bound_shares(bound)
        if "pose_sensor_shape_within_5" in bound["bounds"]["one frame"]["all"]:
            report["bound_shape"] = bound_shares(bound, "pose_sensor_shape")
    publish(report, args.out, markdown)


def bound_shares(info: dict[str, Any], bound: str = "pose_sensor") -> dict[str, Any]:
    """The efficient estimator's share within 5 deg (one frame; by default with the pose and sensor unknown)
    overall and per band, from the JSON of ``benchmarks.angle_information``."""
    rows = info["bounds"]["one frame"]
    pick = {k: v[f"{bound}_within_5"] for k, v in rows.items()}
    return {"all": pick.get("all"), "by_force": {k: v for k, v in pick.items() if k.endswith(" N")},
            "by_object": {k: v for k, v in pick.items()  # reports made since the bound has rows per object
                          if k != "all" and not k.endswith(" N") and not k.startswith("chip noise")}}


def _share(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.1%}"


def markdown(report: dict[str, Any]) -> str:
    bands = [f"{lo:g}-{hi:g} N" for lo, hi in FORCE_BANDS_N]
    lines = [f"Single frames of the {report['presses']} presses of elongated objects (rods, flat bars) in "
             f"{report['data']}'s test split, each as recorded; within 5 deg per band of the pressing force.", "",
             "| route | within 5 deg | within 2 deg | median deg | " + " | ".join(bands) + " |",
             "|---" * (4 + len(bands)) + "|"]
    for key, name in (("bound", "Cramer-Rao bound (pose and sensor unknown)"),
                      ("bound_shape", "Cramer-Rao bound (rod dimensions unknown too)")):
        if key in report:
            b = report[key]
            lines.append(f"| {name} | {b['all']:.1%} | - | - | "
                         + " | ".join(_share(b["by_force"].get(k)) for k in bands) + " |")
    for name, r in report["results"].items():
        lines.append(f"| {name} | {r['within_5']:.1%} | {r['within_2']:.1%} | {r['median_deg']:.2f} | "
                     + " | ".join(_share(r["by_force"].get(k)) for k in bands) + " |")
    spread = [(n, r) for n, r in report["results"].items() if "within_5_range" in r]
    if spread:
        lines += ["", "Over fresh chip draws, the lowest and highest share within 5 deg of one draw:", "",
                  "| route | draws | within 5 deg | at 2-5 N |", "|---|---|---|---|"]
        lines += [f"| {n} | {r['draws']} | {r['within_5_range'][0]:.1%}-{r['within_5_range'][1]:.1%} | "
                  f"{_share(r['within_5_at_2_5_n_range'][0])}-{_share(r['within_5_at_2_5_n_range'][1])} |"
                  for n, r in spread]
    objects = sorted({o for r in report["results"].values() for o in r["by_object"]})
    lines += ["", "Within 5 deg per object:", "", "| route | " + " | ".join(objects) + " |",
              "|---" * (1 + len(objects)) + "|"]
    for key, name in (("bound", "Cramer-Rao bound (pose and sensor unknown)"),
                      ("bound_shape", "Cramer-Rao bound (rod dimensions unknown too)")):
        if report.get(key, {}).get("by_object"):
            lines.append(f"| {name} | " + " | ".join(f"{report[key]['by_object'].get(o, math.nan):.0%}"
                                                     for o in objects) + " |")
    for name, r in report["results"].items():
        lines.append(f"| {name} | " + " | ".join(f"{r['by_object'].get(o, math.nan):.0%}" for o in objects) + " |")
    rel = [(n, r["reliability"]) for n, r in report["results"].items() if r.get("reliability")]
    if rel:
        lines += ["", "Reliability (probability within 5 deg given by the route, against the share observed):", "",
                  "| route | bin | presses | predicted | observed |", "|---|---|---|---|---|"]
        for name, rows in rel:
            lines += [f"| {name} | {x['bin']} | {x['presses']} | {x['predicted']:.2f} | {x['observed']:.2f} |"
                      for x in rows]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
