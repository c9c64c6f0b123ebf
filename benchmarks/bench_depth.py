"""Reading -> depth image on one thread: what each image symmetry of the default model costs and buys.

    python -m benchmarks.bench_depth                      # 240 unseen-rod readings, 3 passes
    python -m benchmarks.bench_depth --readings 60 --repeats 1 --out /tmp/depth.json

The default model's file (``models/supermag.onnx``) stores ``image_symmetry = "rotations"``: each image the
average of 4 decoder passes, one per quarter turn of the reading. The runtime default decodes once
(``image_symmetry="none"``); ``"stored"`` takes the file's average, ``"all"`` the 8 symmetric copies. Per choice,
on one thread, interleaved reading by reading (every call of a reading in turn, so a busy machine slows every
row alike): ``reconstruct`` of one reading, p50 / p99 / max ms, and the image's PSNR / SSIM against the
simulated camera's depth image of the same press (the evaluation's definitions), and the angle error of the
paper's image route on it (``angle_source="image"``: outliers removed, Gaussian filter, PCA). In the same loop,
the acceptance rows of the default estimator (``TactileEstimator.load()``): reading -> angle (the pose part),
reading -> angle, contact state and position (``estimate``: the position decodes the image), and 16 pads -> angles (``estimate_many`` of 16 readings).

Readings are simulated presses of the six unseen rods (random in-hand angle, +-2 mm offset, 10-11 N, chip noise,
nominal sensor), the same as ``bench_pose`` and ``bench_pads``. Prints a markdown table and writes it beside the
JSON (default ``docs/results/benchmarks/depth.json`` and ``.md``). It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one thread, as the table says
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402
from benchmarks.bench_pose import RODS  # noqa: E402
from tactile_manip.evaluation import metrics  # noqa: E402
from tactile_manip.perception import TactileEstimator, TactilePoseEstimator, load_reconstructor, wrap_axial  # noqa: E402
from tactile_manip.sim.objects import IndenterPose  # noqa: E402
from tactile_manip.sim.pair import SensorPair  # noqa: E402
from tactile_manip.sim.shapes import make_indenter  # noqa: E402

CHOICES = ("none", "rotations", "all")  # the runtime default first; the file's "stored" is "rotations"
PASSES = {"none": 1, "rotations": 4, "all": 8}
PADS = 16
BUDGET_MS = {"depth": 2.5, "angle": 1.5, "pads": 4.0}  # p99 on one thread (issue 60's acceptance)


def rod_presses(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` rod presses: readings (n, 4, 4, 3) uT, the camera's depth images (n, 200, 200) mm, true angles (n,)."""
    pair, rng = SensorPair(seed=seed), np.random.default_rng(seed)
    rods = {spec: make_indenter(spec[0], size_mm=spec[1]) for spec in RODS}
    fields, depths, angles = [], [], []
    for i in range(n):
        angle = float(wrap_axial(rng.uniform(-math.pi / 2, math.pi / 2)))
        pose = IndenterPose(*rng.uniform(-2.0, 2.0, size=2), yaw_rad=angle)
        sample = pair.press(rods[RODS[i % len(RODS)]], pose, rng.uniform(10.0, 11.0), rng)
        fields.append(sample.field_ut)
        depths.append(sample.depth_mm)
        angles.append(angle)
    return np.stack(fields), np.stack(depths), np.array(angles)


def _ms(wall: list[float], cpu: list[float], readings: int) -> dict[str, float]:
    """Percentiles of the calls' wall-clock and thread CPU times (ms), and the p99 over readings of each
    reading's fastest call (calls come reading by reading, ``readings`` per pass): on a machine others use,
    the wall clock's tail is mostly the time this thread waited for a core; the other two are not."""
    a, c = np.asarray(wall), np.asarray(cpu)
    best = a.reshape(-1, readings).min(axis=0)
    return {"p50_ms": float(np.percentile(a, 50)), "p99_ms": float(np.percentile(a, 99)), "max_ms": float(a.max()),
            "cpu_p50_ms": float(np.percentile(c, 50)), "cpu_p99_ms": float(np.percentile(c, 99)),
            "best_of_passes_p99_ms": float(np.percentile(best, 99)), "calls": len(a)}


def measure(model: str, readings: int, repeats: int, seed: int) -> dict[str, Any]:
    recs = {c: load_reconstructor(model, threads=1, image_symmetry=c) for c in CHOICES}
    routes = {c: TactilePoseEstimator(r, angle_source="image") for c, r in recs.items()}
    default = TactileEstimator.load(model, threads=1)  # the one way in: shipped pose and contact models
    fields, depths, angles = rod_presses(readings, seed)
    pads = [np.roll(fields, -k, axis=0)[:PADS] for k in range(len(fields))]
    for f in fields[:5]:  # warm-up
        for r in recs.values():
            r.reconstruct(f)
        default.estimate(f)
        default.pose.estimate_many(pads[0])
    keys = (*CHOICES, "angle", "angle_contact", "pads")
    wall: dict[str, list[float]] = {k: [] for k in keys}
    cpu: dict[str, list[float]] = {k: [] for k in keys}
    for _ in range(repeats):
        for i, f in enumerate(fields):
            calls = [(c, lambda c=c: recs[c].reconstruct(f)) for c in CHOICES]
            calls += [("angle", lambda: default.pose.estimate(f)), ("angle_contact", lambda: default.estimate(f)),
                      ("pads", lambda: default.pose.estimate_many(pads[i]))]
            for key, call in calls:
                c0, t0 = time.thread_time(), time.perf_counter()
                call()
                wall[key].append((time.perf_counter() - t0) * 1e3)
                cpu[key].append((time.thread_time() - c0) * 1e3)
    choices = {}
    for c in CHOICES:
        images = np.stack([recs[c].reconstruct(f).depth_mm for f in fields])
        est = [routes[c].estimate(f) for f in fields]
        errors = np.array([abs(math.degrees(wrap_axial(e.angle_rad - a))) if e.defined else 90.0
                           for e, a in zip(est, angles)])
        choices[c] = {"passes": PASSES[c], **_ms(wall[c], cpu[c], readings),
                      "psnr_db": float(np.mean(metrics.psnr(images, depths))),
                      "ssim": float(np.mean(metrics.ssim(images, depths))),
                      "image_route_median_deg": float(np.median(errors)),
                      "image_route_p95_deg": float(np.percentile(errors, 95)),
                      "image_route_within_5deg": float(np.mean(errors <= 5.0))}
    return {"model": str(model), "stored": recs["none"].metadata.get("image_symmetry", "none"),
            "readings": readings, "repeats": repeats, "seed": seed, "choices": choices,
            "estimator": {k: _ms(wall[k], cpu[k], readings) for k in ("angle", "angle_contact", "pads")},
            "budget_p99_ms": BUDGET_MS, "onnxruntime": _ort_version(), "machine": machine_info()}


def _ort_version() -> str:
    import onnxruntime

    return onnxruntime.__version__


def markdown(r: dict[str, Any]) -> str:
    m = r["machine"]
    lines = [f"# Reading -> depth image, one thread ({r['model']})", "",
             f"{r['readings']} unseen-rod readings x {r['repeats']} passes, interleaved; {m['cpu_model']}, "
             f"{m['usable_cores']} usable cores, load average {m['load_average']}, onnxruntime {r['onnxruntime']}, "
             f"{m['time_utc']}; the file stores "
             f"`{r['stored']}`. PSNR / SSIM against the simulated camera's image of the same press; image route: "
             "the paper's angle from that image.", "",
             "Wall: p50 / p99 / max of the calls' wall-clock time; best p99: the p99 over readings of each reading's "
             "fastest call; CPU p99: of the thread's CPU time (the machine's other users take no share of either).",
             "",
             "| image_symmetry | decoder passes | wall p50 / p99 / max ms | best p99 ms | CPU p99 ms | PSNR dB | SSIM | "
             "image-route angle median / p95 deg | within 5 deg |", "|---|---|---|---|---|---|---|---|---|"]
    for c, v in r["choices"].items():
        name = f"`{c}`" + (" (default)" if c == "none" else " (the file's, `stored`)" if c == r["stored"] else "")
        lines.append(f"| {name} | {v['passes']} | {v['p50_ms']:.2f} / {v['p99_ms']:.2f} / {v['max_ms']:.2f} | "
                     f"{v['best_of_passes_p99_ms']:.2f} | {v['cpu_p99_ms']:.2f} | {v['psnr_db']:.2f} | {v['ssim']:.3f} | {v['image_route_median_deg']:.2f} / "
                     f"{v['image_route_p95_deg']:.2f} | {100 * v['image_route_within_5deg']:.1f} % |")
    lines += ["", "| the default estimator (`TactileEstimator.load()`) | wall p50 / p99 / max ms | best p99 ms | "
              "CPU p99 ms | p99 budget |", "|---|---|---|---|---|"]
    for key, label, budget in (("angle", "reading -> angle (pose part)", BUDGET_MS["angle"]),
                               ("angle_contact", "reading -> angle, contact state and position (`estimate`)", None),
                               ("pads", f"{PADS} pads -> angles", BUDGET_MS["pads"])):
        v = r["estimator"][key]
        lines.append(f"| {label} | {v['p50_ms']:.2f} / {v['p99_ms']:.2f} / {v['max_ms']:.2f} | "
                     f"{v['best_of_passes_p99_ms']:.2f} | {v['cpu_p99_ms']:.2f} | "
                     f"{'' if budget is None else f'{budget} ms'} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="supermag", help="a shipped model's name or an .onnx path")
    parser.add_argument("--readings", type=int, default=240)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--out", default="docs/results/benchmarks/depth.json")
    args = parser.parse_args()
    report = measure(args.model, args.readings, args.repeats, args.seed)
    publish(report, args.out, markdown)
    Path(args.out).with_suffix(".md").write_text(markdown(report))


if __name__ == "__main__":
    main()
