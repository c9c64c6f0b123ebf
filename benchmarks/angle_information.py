"""How well could any estimator know a rod's angle from one reading? The Cramer-Rao bound per test press.

    python -m benchmarks.angle_information                         # data/robust.npz: 600 unseen rods, 2-15 N
    python -m benchmarks.angle_information --data data/supermag.npz   # the paper's protocol, for comparison
    python -m benchmarks.angle_information --limit 60 --workers 1     # a quick look
    python -m benchmarks.angle_information --report experiments/robust_training/information/angle_information.json \
        --compare experiments/robust_training/robust_b48/single_frame.json --plot bound.png   # the bound beside models

Each unseen-rod press of the dataset's test split is rebuilt from what the dataset recorded (its drawn sensor
from the ``sensor_params`` extra, or the nominal sensor; its pose; its force; the rod), and the noise-free
reading as the dataset records it (the chips' expected values, misalignment included, less that sensor's own
unloaded reading, so that a sensor parameter moves it only through the press) is differentiated by central
differences with respect to the rod's in-plane angle and the nuisances a real estimator does not know: the
rod's x and y offsets, the force and the two tilts, and the drawn sensor's magnet remanence, chip gap and skin
modulus. The chips' Gaussian noise (the drawn sigma_xy and sigma_z, plus the quantisation step's variance,
plus the per-press drift as more noise unless the baseline is tared just before the press) makes a reading
Gaussian about that value, so the Fisher information J of its 48 channels bounds the standard deviation of any
unbiased angle estimate:

- ``oracle``: everything but the angle known: sigma >= 1 / sqrt(J_aa), the most optimistic bound;
- ``pose``: the offsets, force and tilts unknown as well: sigma >= sqrt([J^-1]_aa) over those parameters;
- ``pose_sensor``: the sensor's remanence, gap and skin modulus unknown too;
- ``pose_sensor_shape``: the rod's dimensions unknown as well (its size, length, and a flat bar's width and
  thickness), as they are to a method that meets the rod for the first time. The section's kind (round, hex,
  square, flat) stays known: a discrete unknown has no derivative, so this is still an upper bound.

Saturated channels carry no information. The share of presses within 5 deg (2 deg) that an efficient estimator
would reach is the mean over presses of erf(tol / (sqrt(2) sigma)). Where the signal is weak the bound is
loose (estimators there have threshold effects, e.g. a 90 deg ambiguity, that the local bound does not see),
so these shares are upper bounds on what any method can do from such readings, not predictions. Reported for
one frame as the dataset records it (drift included), four frames averaged, and one frame after a tare (drift
removed); per force band, per tercile of the drawn chip noise and per object. Prints markdown and writes
docs/results/benchmarks/angle_information.json; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.data import load_dataset

RODS = ("cylinder", "hex_bar", "square_bar", "flat_bar")
STEPS = {"angle_rad": math.radians(1.0), "x_mm": 0.1, "y_mm": 0.1, "force_rel": 0.02, "tilt_rad": math.radians(0.5),
         "sensor_rel": 0.02}
POSE_NUISANCES = ("x_mm", "y_mm", "force_n", "tilt_x_rad", "tilt_y_rad")
SENSOR_NUISANCES = ("magnet.remanence_t", "magnet.chip_gap_mm", "layer.skin_modulus_kpa")
SHAPE_NUISANCES = ("size_mm", "length_mm", "width_mm", "thickness_mm")  # those the rod's kind has
SHAPE_STEP_MM = 0.2  # two pixels of the indenter's height map: a finer step would not change the map
BOUNDS = ("oracle", "pose", "pose_sensor", "pose_sensor_shape")
FORCE_BANDS_N = ((2.0, 5.0), (5.0, 8.0), (8.0, 11.0), (11.0, 15.0))
TOLERANCES_DEG = (5.0, 2.0)
CASES = {"one frame": (1, True), "four frames averaged": (4, True), "one frame, baseline tared": (1, False)}


def rod_presses(data, split: str) -> tuple[np.ndarray, dict[str, tuple[str, dict]]]:
    """Indices of the rod presses of ``split`` and each rod label's (kind, kwargs) from the dataset's config."""
    objects = data.provenance["config"]["objects"]
    specs = {(o.get("label") or o["name"]): (o["name"], o.get("kwargs", {})) for o in objects}
    names = data.object_names
    idx = [i for i in data.indices(split) if specs.get(names[data.object_index[i]], ("",))[0] in RODS]
    return np.array(idx, dtype=int), specs


def _jobs(data, idx: np.ndarray, specs: dict) -> list[dict[str, Any]]:
    names = data.provenance.get("sensor_param_names")
    drawn = data.extra("sensor_params") if data.has("sensor_params") else None
    saturated = data.extra("saturated") if data.has("saturated") else np.zeros((len(data.readings), 4, 4, 3), bool)
    seed = int(data.provenance["config"].get("sensor_seed", 0))
    jobs = []
    for i in idx:
        label = str(data.object_names[data.object_index[i]])
        kind, kwargs = specs[label]
        jobs.append({"index": int(i), "label": label, "kind": kind, "kwargs": kwargs, "sensor_seed": seed,
                     "params": None if drawn is None else dict(zip(names, map(float, drawn[i]))),
                     "pose": [float(v) for v in data.extra("pose")[i]], "force_n": float(data.extra("force_n")[i]),
                     "saturated": saturated[i].tolist()})
    return jobs


def _information(job: dict[str, Any]) -> dict[str, Any]:
    """The derivatives of one press's noise-free reading (48,) with respect to the angle and each nuisance
    (central differences, in the order of ``PARAMETERS``), and its noise: what the Fisher matrix needs."""
    from tactile_manip.boards import load_board
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.sim.params import for_board, randomised_values, with_values
    from tactile_manip.sim.shapes import make_indenter

    params = for_board(load_board("supermag-4x4"))
    if job["params"] is not None:
        params = with_values(params, job["params"])
    nominal = SensorPair(params, seed=job["sensor_seed"])
    rod = make_indenter(job["kind"], **job["kwargs"])
    sizes = shape_sizes(job["kind"], job["kwargs"])
    pose0, force = np.asarray(job["pose"], float), job["force_n"]

    def reading(pose: np.ndarray, scale: float = 1.0, pair: SensorPair = nominal, shape: Any = rod) -> np.ndarray:
        # as recorded: less the sensor's own unloaded reading, so a sensor parameter moves it only through the press
        return pair.expected_reading_ut(shape, IndenterPose(*pose), force * scale).ravel()

    def along_pose(k: int, step: float) -> np.ndarray:
        e = np.zeros(5)
        e[k] = step
        return (reading(pose0 + e) - reading(pose0 - e)) / (2 * step)

    def along_sensor(name: str, rel: float) -> np.ndarray:
        value = randomised_values(params)[name]
        pairs = [SensorPair(with_values(params, {name: value * (1 + sign * rel)}), seed=job["sensor_seed"])
                 for sign in (1, -1)]
        return (reading(pose0, pair=pairs[0]) - reading(pose0, pair=pairs[1])) / (2 * rel * value)

    def along_shape(name: str) -> np.ndarray:
        # central where the shape allows both sides, else one-sided (an 8 mm rod is the largest one can make)
        for hi, lo in ((1, -1), (1, 0), (0, -1)):
            try:
                shapes = [make_indenter(job["kind"], **(job["kwargs"] | {name: sizes[name] + k * SHAPE_STEP_MM}))
                          for k in (hi, lo)]
            except ValueError:
                continue
            return (reading(pose0, shape=shapes[0]) - reading(pose0, shape=shapes[1])) / ((hi - lo) * SHAPE_STEP_MM)
        raise ValueError(f"{job['kind']}: {name} = {sizes[name]} mm cannot be varied by {SHAPE_STEP_MM} mm")

    columns = [along_pose(2, STEPS["angle_rad"]), along_pose(0, STEPS["x_mm"]), along_pose(1, STEPS["y_mm"]),
               (reading(pose0, 1 + STEPS["force_rel"]) - reading(pose0, 1 - STEPS["force_rel"]))
               / (2 * STEPS["force_rel"] * force),
               along_pose(3, STEPS["tilt_rad"]), along_pose(4, STEPS["tilt_rad"]),
               *[along_sensor(name, STEPS["sensor_rel"]) for name in SENSOR_NUISANCES],
               *[along_shape(name) for name in sizes]]
    coarse = along_pose(2, 3 * STEPS["angle_rad"])  # the angle's derivative again, at three times the step
    c = params.chip
    return {"index": job["index"], "label": job["label"], "force_n": force, "jacobian": np.stack(columns, 1).tolist(),
            "white_var": white_var(c).tolist(), "drift_var": c.drift_ut ** 2, "noise_xy_ut": c.noise_xy_ut,
            "saturated": np.asarray(job["saturated"], bool).ravel().tolist(), "shape_nuisances": list(sizes),
            "step_check": float(np.linalg.norm(coarse - columns[0]) / max(np.linalg.norm(columns[0]), 1e-12))}


def white_var(chip: Any) -> np.ndarray:
    """Each channel's (48,) white variance (uT^2) in one frame of the chip model ``chip``: its Gaussian noise and
    its quantisation step's, without the drift."""
    noise = np.tile([chip.noise_xy_ut, chip.noise_xy_ut, chip.noise_z_ut], 16) ** 2
    return noise + np.tile([chip.lsb_xy_ut, chip.lsb_xy_ut, chip.lsb_z_ut], 16) ** 2 / 12.0


def shape_sizes(kind: str, kwargs: dict[str, Any]) -> dict[str, float]:
    """The rod's dimensions among ``SHAPE_NUISANCES`` (mm): those of ``kwargs``, else the shape's defaults."""
    import inspect

    from tactile_manip.sim.shapes import SHAPES

    params = inspect.signature(SHAPES[kind]).parameters
    return {name: float(kwargs.get(name, params[name].default)) for name in SHAPE_NUISANCES if name in params}


def bounds_deg(info: dict[str, Any], frames: int, drift: bool) -> tuple[float, ...]:
    """The bounds (deg) on the angle's standard deviation for one press: everything else known (oracle), the
    pose and force unknown, the sensor's magnet, gap and skin unknown as well, and the rod's dimensions too
    (the last equals the third for a press computed without them)."""
    jac = np.asarray(info["jacobian"])
    var = np.asarray(info["white_var"]) / frames + (info["drift_var"] if drift else 0.0)
    jac = np.where(np.asarray(info["saturated"])[:, None], 0.0, jac)
    fisher = jac.T @ (jac / var[:, None])
    out = []
    for n in (1, 1 + len(POSE_NUISANCES), 1 + len(POSE_NUISANCES) + len(SENSOR_NUISANCES), fisher.shape[0]):
        # the angle's information left once the nuisances are estimated too: the Schur complement of their block,
        # through a pseudo-inverse. The block can be singular: a nuisance that does not move the reading (a
        # rod's far end off the pad; the offset along a centred bar) or two that move it alike. A matrix inverse
        # fails there; projecting the nuisances out gives the angle what the reading carries. Columns are scaled
        # to unit information first (their units differ: mm, N, rad, T, kPa).
        angle_info = fisher[0, 0]
        nuisance, cross = fisher[1:n, 1:n], fisher[0, 1:n]
        scale = np.sqrt(np.diag(nuisance))
        moves = scale > 0
        if moves.any():
            unit = scale[moves]
            corr = nuisance[np.ix_(moves, moves)] / np.outer(unit, unit)
            c = cross[moves] / unit
            angle_info -= float(c @ np.linalg.pinv(corr, rcond=1e-10, hermitian=True) @ c)
        out.append(math.degrees(1.0 / math.sqrt(angle_info)) if angle_info > 0 else math.inf)
    return tuple(out)


def within(sigma_deg: np.ndarray, tol_deg: float) -> float:
    """The mean over presses of P(|N(0, sigma^2)| < tol): an efficient estimator's share within ``tol``."""
    return float(np.mean([math.erf(tol_deg / (math.sqrt(2) * s)) if s > 0 else 1.0 for s in sigma_deg]))


def summarise(infos: list[dict[str, Any]]) -> dict[str, Any]:
    force = np.array([i["force_n"] for i in infos])
    noise = np.array([i["noise_xy_ut"] for i in infos])
    terciles = np.quantile(noise, [1 / 3, 2 / 3]) if len(set(noise)) > 1 else None
    groups = {"all": np.ones(len(infos), bool)}
    groups |= {f"{lo:g}-{hi:g} N": (force >= lo) & (force < hi) for lo, hi in FORCE_BANDS_N}
    if terciles is not None:
        groups |= {"chip noise low third": noise <= terciles[0],
                   "chip noise mid third": (noise > terciles[0]) & (noise <= terciles[1]),
                   "chip noise high third": noise > terciles[1]}
    labels = np.array([i["label"] for i in infos])
    if len(set(labels)) > 1:
        groups |= {str(name): labels == name for name in sorted(set(labels))}
    out: dict[str, Any] = {}
    for case, (frames, drift) in CASES.items():
        sig = np.array([bounds_deg(i, frames, drift) for i in infos])
        out[case] = {}
        for name, sel in groups.items():
            if not sel.any():
                continue
            row = {"presses": int(sel.sum())}
            for k, label in enumerate(BOUNDS):
                row[f"{label}_median_sigma_deg"] = float(np.median(sig[sel, k]))
                for tol in TOLERANCES_DEG:
                    row[f"{label}_within_{tol:g}"] = within(sig[sel, k], tol)
            out[case][name] = row
    return out


def markdown(report: dict[str, Any]) -> str:
    lines = [f"Angle information on {report['source']}: {report['presses']} unseen-rod presses, rebuilt in "
             f"{report['seconds']:.0f} s; Cramer-Rao bounds on the angle's standard deviation (median sigma) and "
             f"the share an efficient estimator would get within 5 / 2 deg. Known: oracle, everything but the "
             f"angle; pose, the offsets, force and tilts unknown too; + sensor, the magnet's remanence, chip gap "
             f"and skin modulus unknown as well; + rod dimensions, its size, length, width and thickness (those its "
             f"kind has) unknown too. Derivative check: the angle's derivative at 3 deg steps differs "
             f"from the 1 deg one by {report['step_check_median']:.1%} (median), "
             f"{report['step_check_p95']:.1%} (p95).", ""]
    for case, groups in report["bounds"].items():
        lines += [f"**{case}**", "", "| presses | n | oracle sigma deg | oracle within 5 / 2 deg | pose unknown sigma "
                  "| within 5 / 2 deg | + sensor unknown sigma | within 5 / 2 deg | + rod dimensions unknown sigma "
                  "| within 5 / 2 deg |", "|---|---|---|---|---|---|---|---|---|---|"]
        for name, r in groups.items():
            cells = [f"{r[f'{b}_median_sigma_deg']:.2f} | {r[f'{b}_within_5']:.1%} / {r[f'{b}_within_2']:.1%}"
                     if f"{b}_median_sigma_deg" in r else " | " for b in BOUNDS]  # a report without this bound
            lines.append(f"| {name} | {r['presses']} | " + " | ".join(cells) + " |")
        lines.append("")
    lines.append("The shares are upper bounds for efficient unbiased estimators (erf of the tolerance over the "
                 "bound); where the signal is weak a real method does worse than its bound.")
    return "\n".join(lines)


def plot(report: dict[str, Any], compare: list[str], path: str) -> None:
    """Share within 5 deg per force band: the bounds (one frame; after a tare), beside the methods of each
    ``tactile-manip evaluate`` results.json in ``compare`` (their per-force rod angles), or of each route of a
    ``benchmarks.angle_ablation`` report."""
    from tactile_manip.plots import _pyplot

    bands = [f"{lo:g}-{hi:g} N" for lo, hi in FORCE_BANDS_N]
    series = {"bound, one frame (pose and sensor unknown)":
              [report["bounds"]["one frame"][b]["pose_sensor_within_5"] for b in bands]}
    if "pose_sensor_shape_within_5" in report["bounds"]["one frame"]["all"]:
        series["bound, one frame (rod dimensions unknown too)"] = [
            report["bounds"]["one frame"][b]["pose_sensor_shape_within_5"] for b in bands]
    series["bound, one frame after a tare"] = [report["bounds"]["one frame, baseline tared"][b]["pose_sensor_within_5"]
                                               for b in bands]
    for file in compare:
        results = json.loads(Path(file).read_text())["results"]
        if isinstance(results, dict):  # benchmarks.angle_ablation: one row per model and route
            for name, res in results.items():
                if all(b in res["by_force"] for b in bands) and not any(
                        skip in name for skip in ("likelier", "raw probability", "default: image")):
                    series[name] = [res["by_force"][b] for b in bands]
            continue
        for res in results:
            force = res.get("per_group", {}).get("force", {})
            if all(b in force for b in bands):
                series[res["method"]] = [force[b]["angle_within_5_deg"] for b in bands]
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 4.8 + 0.25 * len(series)), constrained_layout=True)
    width = 0.8 / len(series)
    for k, (name, values) in enumerate(series.items()):
        hatch = "//" if name.startswith("bound") else None
        ax.bar(np.arange(len(bands)) + (k - (len(series) - 1) / 2) * width, [100 * v for v in values], width,
               label=name, hatch=hatch, edgecolor="black" if hatch else None, alpha=0.6 if hatch else 1.0)
    ax.axhline(95, color="grey", linestyle="--", linewidth=1)
    ax.set_xticks(np.arange(len(bands)), bands)
    ax.set_ylabel("unseen bars within 5 deg [%]")
    ax.set_ylim(0, 102)
    ax.set_title(f"One reading: the Cramer-Rao bound against the methods ({report['source']})", fontsize=10)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncols=2)  # long names: two columns fit
    fig.savefig(path, dpi=100)
    plt.close(fig)
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="data/robust.npz")
    parser.add_argument("--split", default="test")
    parser.add_argument("--limit", type=int, default=0, help="the first N rod presses only (0: all)")
    parser.add_argument("--workers", type=int, default=0, help="processes (0: all cores)")
    parser.add_argument("--out", default="docs/results/benchmarks/angle_information.json")
    parser.add_argument("--report", default=None,
                        help="an earlier run's JSON: plot it (with --plot) instead of computing again")
    parser.add_argument("--compare", action="append", default=[], metavar="RESULTS.json",
                        help="a `tactile-manip evaluate` results.json on the same data: its methods in the plot")
    parser.add_argument("--plot", default=None, help="PNG of the share within 5 deg per force band")
    args = parser.parse_args()
    if args.report:
        report = json.loads(Path(args.report).read_text())
    else:
        report = compute(args)
        publish(report, args.out, markdown)
    if args.plot:
        plot(report, args.compare, args.plot)


def compute(args: argparse.Namespace) -> dict[str, Any]:
    data = load_dataset(args.data)
    idx, specs = rod_presses(data, args.split)
    if args.limit:
        idx = idx[:args.limit]
    jobs = _jobs(data, idx, specs)
    start = time.perf_counter()
    workers = args.workers or os.cpu_count() or 1
    if workers == 1:
        infos = [_information(j) for j in jobs]
    else:
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            infos = list(pool.map(_information, jobs, chunksize=8))
    checks = [i["step_check"] for i in infos]
    return {"machine": machine_info(), "source": f"{args.data} {args.split} split", "presses": len(infos),
            "seconds": time.perf_counter() - start, "steps": STEPS, "nuisances": POSE_NUISANCES + SENSOR_NUISANCES,
            "step_check_median": float(np.median(checks)), "step_check_p95": float(np.percentile(checks, 95)),
            "bounds": summarise(infos),
            "per_press": [{k: v for k, v in i.items() if k not in ("jacobian", "white_var", "saturated")}
                          | dict(zip([f"{b}_sigma_deg" for b in BOUNDS], bounds_deg(i, 1, True))) for i in infos]}


if __name__ == "__main__":
    main()
