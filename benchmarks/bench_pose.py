"""End-to-end tactile pose: reading -> angle latency (one and two pads) against angle error, per method.

    python -m benchmarks.bench_pose                        # shipped SuperMag (one pass and symmetry-averaged),
                                                           # bilinear 16x16 and 200x200, the paper preset
    python -m benchmarks.bench_pose --readings 300 --method mine=path/to/model.onnx
    python -m benchmarks.bench_pose --untrained fast=configs/train/candidate.toml   # latency of a config
    python -m benchmarks.bench_pose --candidates           # also every experiments/decoder_candidates/decoder_*.toml,
                                                           # untrained

Readings are simulated presses of the six unseen rods (random in-hand angle, +-2 mm offset, 10-11 N, chip
noise), the same for every method. Per method, on one thread: latency p50 / p99 of
``TactilePoseEstimator.estimate`` (reconstruction + outlier removal + filter + PCA), the p99 over readings
of each reading's fastest call (the cost the machine's jitter does not explain), and the share of it spent
after the reconstruction; of ``estimate_many`` on two pads' readings (one batched model run, time per pair);
and the angle error median / p95 / share within 5 deg. The paper preset (and every ``--untrained`` config) is
an untrained export, timed only (latency does not depend on the weights; at most ``--slow-calls`` calls), and
every method's p50 is compared with it. Prints a markdown table and writes docs/results/benchmarks/pose.json. It
measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one thread, as the table says
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402
from tactile_manip.perception import TactilePoseEstimator, load_reconstructor, wrap_axial  # noqa: E402
from tactile_manip.perception.symmetry import SymmetrizedReconstructor  # noqa: E402
from tactile_manip.sim.objects import IndenterPose  # noqa: E402
from tactile_manip.sim.pair import SensorPair  # noqa: E402
from tactile_manip.sim.shapes import make_indenter  # noqa: E402

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


def measure(estimator: TactilePoseEstimator, fields: np.ndarray, angles: np.ndarray, repeats: int, *,
            max_calls: int | None = None, untrained: bool = False) -> dict[str, Any]:
    """One pad (``estimate``), then two pads (``estimate_many`` of each reading and the next), interleaved
    reading by reading so a busy machine slows both alike; ``repeats`` passes, at most ``max_calls`` each."""
    pairs = np.stack([fields, np.roll(fields, -1, axis=0)], axis=1)  # (N, 2, R, C, 3)
    for f, pair in zip(fields[:5], pairs[:5]):  # warm-up (both batch sizes)
        estimator.estimate(f)
        estimator.estimate_many(pair)
    one_ms, pair_ms, model_s, post_s, total_s, errors = [], [], [], [], [], []
    best_ms: dict[int, float] = {}  # each reading's fastest one-pad call: its cost without the machine's jitter
    order = [i for _ in range(repeats) for i in range(len(fields))][:max_calls]
    for i in order:
        t0 = time.perf_counter()
        est = estimator.estimate(fields[i])
        t1 = time.perf_counter()
        estimator.estimate_many(pairs[i])
        t2 = time.perf_counter()
        one_ms.append((t1 - t0) * 1e3)
        best_ms[i] = min(best_ms.get(i, math.inf), one_ms[-1])
        pair_ms.append((t2 - t1) * 1e3)
        model_s.append(est.timings_s.get("reconstruct", 0.0))  # 0 where the head answered (no image)
        post_s.append(est.timings_s.get("pose", 0.0))
        total_s.append(est.timings_s["total"])
        if len(errors) < len(fields):
            errors.append(abs(math.degrees(wrap_axial(est.angle_rad - angles[i]))) if est.defined else 90.0)
    model_ms, post_ms = np.array(model_s) * 1e3, np.array(post_s) * 1e3
    out = {"latency_p50_ms": _pct(one_ms, 50), "latency_p99_ms": _pct(one_ms, 99), "pair_p50_ms": _pct(pair_ms, 50),
           "pair_p99_ms": _pct(pair_ms, 99), "model_p50_ms": _pct(model_ms, 50), "model_p99_ms": _pct(model_ms, 99),
           "postprocess_p50_ms": _pct(post_ms, 50), "postprocess_p99_ms": _pct(post_ms, 99),
           "postprocess_share": float(sum(post_s) / sum(total_s)),
           "best_p99_ms": _pct(list(best_ms.values()), 99),
           "readings": int(len(fields)), "calls": len(one_ms), "untrained": untrained}
    if not untrained:
        err = np.array(errors)
        out |= {"angle_error_median_deg": float(np.median(err)), "angle_error_p95_deg": float(np.percentile(err, 95)),
                "within_5deg": float((err <= 5.0).mean())}
    return out


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q))


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    paper = report["methods"].get("paper", {}).get("latency_p50_ms")
    lines = [f"End-to-end pose (reading -> angle), one thread, {report['readings']} unseen-rod readings; "
             f"{m['cpu_model']}, {m['usable_cores']} cores, load average {m.get('load_average')}; sensor period "
             f"{PERIOD_MS:g} ms", "",
             "| method | 1 pad p50 ms | 1 pad p99 ms | 1 pad p99 of best ms | 2 pads p50 ms | 2 pads p99 ms | "
             "model p50 / p99 ms | post-processing p50 / p99 ms (share) | x faster than paper (p50) | "
             "angle error median deg | p95 deg | within 5 deg |", "|---" * 12 + "|"]
    for name, r in report["methods"].items():
        ratio = "-" if paper is None or name == "paper" else f"{paper / r['latency_p50_ms']:.0f}x"
        accuracy = (["n/a (untrained)"] * 3 if r["untrained"] else [f"{r['angle_error_median_deg']:.2f}",
                                                                     f"{r['angle_error_p95_deg']:.2f}",
                                                                     f"{r['within_5deg']:.1%}"])
        lines.append(f"| {name} | {r['latency_p50_ms']:.2f} | {r['latency_p99_ms']:.2f} | {r['best_p99_ms']:.2f} | "
                     f"{r['pair_p50_ms']:.2f} | {r['pair_p99_ms']:.2f} | {r['model_p50_ms']:.2f} / "
                     f"{r['model_p99_ms']:.2f} | {r['postprocess_p50_ms']:.2f} / {r['postprocess_p99_ms']:.2f} "
                     f"({r['postprocess_share']:.0%}) | {ratio} | " + " | ".join(accuracy) + " |")
    lines += ["", f"p99 of best: the p99 over readings of each reading's fastest one-pad call in "
              f"{report.get('repeats', '?')} passes, the cost that the machine's jitter does not explain (a large "
              "contact costs more to post-process).",
              "Untrained rows: their images are not contacts, so their post-processing is not representative; "
              "their reading -> angle is about their model time plus a trained model's post-processing."]
    return "\n".join(lines)


def untrained_model(name: str, config: str, folder: Path) -> Path:
    """Export an untrained model of the preset or training config ``config`` (torch needed) for timing."""
    from tactile_manip.learning.cvae.eager import export_untrained

    return export_untrained(config, folder / name)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readings", type=int, default=120)
    parser.add_argument("--repeats", type=int, default=3, help="passes over the readings for the latency")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--method", action="append", default=[], metavar="NAME=MODEL.onnx")
    parser.add_argument("--untrained", action="append", default=[], metavar="NAME=PRESET|CONFIG.toml",
                        help="also time an untrained export of this preset or training config (latency only)")
    parser.add_argument("--candidates", action="store_true",
                        help="also time every experiments/decoder_candidates/decoder_*.toml (untrained) not given "
                        "with --method")
    parser.add_argument("--no-paper", action="store_true", help="skip the paper preset (needs torch to export)")
    parser.add_argument("--slow-calls", type=int, default=40, help="calls at most for the untrained models")
    parser.add_argument("--out", default="docs/results/benchmarks/pose.json")
    args = parser.parse_args()
    shipped = load_reconstructor("experiments/model_variants/supermag_fast.onnx", threads=1)
    methods = {"supermag_fast": shipped, "supermag_fast_sym": SymmetrizedReconstructor(shipped),
               # the model shipped before it: slower, the accuracy reference the fast one had to match
               "supermag_compact": load_reconstructor("experiments/model_variants/supermag_compact.onnx", threads=1),
               "bilinear_16px": load_reconstructor("bilinear", output_px=16),
               "bilinear_200px": load_reconstructor("bilinear")}
    for spec in args.method:
        name, _, path = spec.partition("=")
        methods[name] = load_reconstructor(path, threads=1)
    untrained = dict(spec.partition("=")[::2] for spec in args.untrained)
    if args.candidates:
        configs = sorted(Path("experiments/decoder_candidates").glob("decoder_*.toml"))
        untrained |= {p.stem: str(p) for p in configs if p.stem not in methods}
    if not args.no_paper:
        untrained = {"paper": "paper", **untrained}
    fields, angles = rod_readings(args.readings, args.seed)
    results = {name: measure(TactilePoseEstimator(rec), fields, angles, args.repeats) for name, rec in methods.items()}
    with tempfile.TemporaryDirectory(prefix="bench-pose-") as tmp:
        for name, config in untrained.items():
            rec = load_reconstructor(untrained_model(name, config, Path(tmp)), threads=1)
            results[name] = measure(TactilePoseEstimator(rec), fields, angles, args.repeats,
                                    max_calls=args.slow_calls if name == "paper" else None, untrained=True)
            del rec
    report = {"machine": machine_info(), "readings": args.readings, "repeats": args.repeats, "untrained": untrained,
              "methods": results}
    publish(report, args.out, markdown)


if __name__ == "__main__":
    main()
