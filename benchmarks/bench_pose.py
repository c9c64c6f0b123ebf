"""End-to-end tactile pose: reading -> angle latency against angle error, per method.

    python -m benchmarks.bench_pose                        # shipped SuperMag (one pass and symmetry-averaged),
                                                           # bilinear 16x16 and 200x200
    python -m benchmarks.bench_pose --readings 300 --method mine=path/to/model.onnx

Readings are simulated presses of the six unseen rods (random in-hand angle, +-2 mm offset, 10-11 N, chip
noise), the same for every method. Per method: latency p50 / p99 of ``TactilePoseEstimator.estimate`` on one
thread (reconstruction + outlier removal + filter + PCA), and the angle error median / p95 / share within
5 deg. Prints a markdown table and writes benchmarks/results/pose.json. It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.perception import TactilePoseEstimator, load_reconstructor, wrap_axial
from tactile_manip.perception.symmetry import SymmetrizedReconstructor
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.shapes import make_indenter

RODS = [("cylinder", 3.0), ("hex_bar", 4.0), ("square_bar", 2.5), ("cylinder", 6.0), ("hex_bar", 8.0),
        ("square_bar", 5.0)]
PERIOD_MS = 8.0  # the sensor's 125 Hz frame period


def rod_readings(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` simulated rod readings (n, 4, 4, 3) uT and their true axial angles (n,) rad."""
    pair, rng = SensorPair(seed=seed), np.random.default_rng(seed)
    rods = {spec: make_indenter(spec[0], size_mm=spec[1]) for spec in RODS}
    fields, angles = [], []
    for i in range(n):
        angle = float(wrap_axial(rng.uniform(-math.pi / 2, math.pi / 2)))
        pose = IndenterPose(*rng.uniform(-2.0, 2.0, size=2), yaw_rad=angle)
        sample = pair.press(rods[RODS[i % len(RODS)]], pose, rng.uniform(10.0, 11.0), rng, render_depth=False)
        fields.append(sample.field_ut)
        angles.append(angle)
    return np.stack(fields), np.array(angles)


def measure(estimator: TactilePoseEstimator, fields: np.ndarray, angles: np.ndarray, repeats: int) -> dict[str, Any]:
    for f in fields[:10]:  # warm-up
        estimator.estimate(f)
    latencies, errors = [], []
    for _ in range(repeats):
        for f, a in zip(fields, angles):
            t0 = time.perf_counter()
            est = estimator.estimate(f)
            latencies.append(time.perf_counter() - t0)
            if len(errors) < len(fields):
                errors.append(abs(math.degrees(wrap_axial(est.angle_rad - a))) if est.defined else 90.0)
    lat_ms, err = np.array(latencies) * 1e3, np.array(errors)
    return {"latency_p50_ms": float(np.percentile(lat_ms, 50)), "latency_p99_ms": float(np.percentile(lat_ms, 99)),
            "angle_error_median_deg": float(np.median(err)), "angle_error_p95_deg": float(np.percentile(err, 95)),
            "within_5deg": float((err <= 5.0).mean()), "readings": int(len(fields)), "calls": len(latencies)}


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [f"End-to-end pose (reading -> angle), one thread, {report['readings']} unseen-rod readings; "
             f"{m['cpu_model']}, {m['usable_cores']} cores; sensor period {PERIOD_MS:g} ms", "",
             "| method | p50 ms | p99 ms | angle error median deg | p95 deg | within 5 deg |", "|---|---|---|---|---|---|"]
    for name, r in report["methods"].items():
        lines.append(f"| {name} | {r['latency_p50_ms']:.2f} | {r['latency_p99_ms']:.2f} | "
                     f"{r['angle_error_median_deg']:.2f} | {r['angle_error_p95_deg']:.2f} | {r['within_5deg']:.1%} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readings", type=int, default=120)
    parser.add_argument("--repeats", type=int, default=3, help="passes over the readings for the latency")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--method", action="append", default=[], metavar="NAME=MODEL.onnx")
    parser.add_argument("--out", default="benchmarks/results/pose.json")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    shipped = load_reconstructor("models/supermag_compact.onnx", threads=1)
    methods = {"supermag_compact": shipped, "supermag_compact_sym": SymmetrizedReconstructor(shipped),
               "bilinear_16px": load_reconstructor("bilinear", output_px=16),
               "bilinear_200px": load_reconstructor("bilinear")}
    for spec in args.method:
        name, _, path = spec.partition("=")
        methods[name] = load_reconstructor(path, threads=1)
    fields, angles = rod_readings(args.readings, args.seed)
    report = {"machine": machine_info(), "readings": args.readings,
              "methods": {name: measure(TactilePoseEstimator(rec), fields, angles, args.repeats)
                          for name, rec in methods.items()}}
    publish(report, args.out, markdown)


if __name__ == "__main__":
    main()
