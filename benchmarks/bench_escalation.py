"""Extra inference only when the confidence is low: accuracy and cost of escalating at each confidence level.

    python -m benchmarks.bench_escalation                          # shipped model on data/robust.npz's rods
    python -m benchmarks.bench_escalation --model m.onnx --data d.npz --levels 0.5,0.9

On the unseen-rod presses of the test split (2-15 N, a drawn sensor per press for data/robust.npz), each press
is estimated once by the model (one pass, with the calibration beside the model when there is one) and once by
each escalation: the reading's 8 symmetric copies averaged ("symmetry") and K prior samples ("samples"). For
each confidence level, the presses whose first estimate is below it take the escalation's estimate; the table
gives the share escalated, the angle within 2 and 5 deg, and the latency: p50 / p99 of the one-pass estimate
and of the escalation (one thread, timed on ``--timed`` presses), and the mean per press at that level (one
pass + share x escalation). Writes docs/results/benchmarks/escalation.json. It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one thread, as the table says
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402
from tactile_manip.data import load_dataset  # noqa: E402
from tactile_manip.perception import TactilePoseEstimator, load_reconstructor  # noqa: E402
from tactile_manip.perception.confidence import load_calibration_beside  # noqa: E402
from tactile_manip.evaluation.images import rod_estimates  # noqa: E402
from tactile_manip.perception.symmetry import SymmetrizedReconstructor  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _latency_ms(estimator: TactilePoseEstimator, fields: np.ndarray) -> np.ndarray:
    estimator.estimate(fields[0])  # warm-up
    out = []
    for f in fields:
        t0 = time.perf_counter()
        estimator.estimate(f)
        out.append(1e3 * (time.perf_counter() - t0))
    return np.array(out)


def run(model: Path, data_path: Path, levels: list[float], samples: int, timed: int) -> dict[str, Any]:
    data = load_dataset(data_path)
    calibration = load_calibration_beside(model)
    one = load_reconstructor(model, threads=1)
    escalations = {"symmetry": SymmetrizedReconstructor(one),
                   f"samples_{samples}": load_reconstructor(model, threads=1, samples=samples)}
    base = TactilePoseEstimator(one, calibration=calibration)
    idx, conf, err = rod_estimates(data, data.indices("test"), base)
    fields = data.readings[idx[:timed]].astype(np.float64)
    lat = {"one_pass": _latency_ms(base, fields)}
    report: dict[str, Any] = {"machine": machine_info(), "model": str(model), "data": str(data_path),
                              "calibrated": calibration is not None, "presses": int(idx.size), "escalations": {}}
    for name, rec in escalations.items():
        esc = TactilePoseEstimator(rec, calibration=calibration)
        _, esc_conf, esc_err = rod_estimates(data, idx, esc)
        lat[name] = _latency_ms(esc, fields)
        rows = []
        for level in levels:
            low = conf < level
            e = np.where(low, esc_err, err)
            rows.append({"level": level, "escalated": float(low.mean()), "within_2_deg": float(np.mean(e <= 2)),
                         "within_5_deg": float(np.mean(e <= 5)), "p95_deg": float(np.percentile(e, 95)),
                         "mean_ms": float(np.mean(lat["one_pass"]) + low.mean() * np.mean(lat[name]))})
        report["escalations"][name] = rows
    report["latency_ms"] = {k: {"p50": float(np.median(v)), "p99": float(np.percentile(v, 99)),
                                "mean": float(v.mean())} for k, v in lat.items()}
    return report


def markdown(r: dict[str, Any]) -> str:
    lat = r["latency_ms"]
    lines = [f"Escalation on {r['presses']} unseen-rod presses of {r['data']} ({r['model']}, "
             f"{'calibrated' if r['calibrated'] else 'raw'} confidence)", "",
             "latency, one thread: " + ", ".join(f"{k} p50 {v['p50']:.2f} / p99 {v['p99']:.2f} ms"
                                                 for k, v in lat.items()), "",
             "| escalation | below confidence | escalated | within 2 deg | within 5 deg | p95 deg | mean ms/press |",
             "|---|---|---|---|---|---|---|"]
    for name, rows in r["escalations"].items():
        for row in rows:
            lines.append(f"| {name} | {row['level']:.2f} | {100 * row['escalated']:.1f} % | "
                         f"{100 * row['within_2_deg']:.1f} % | {100 * row['within_5_deg']:.1f} % | "
                         f"{row['p95_deg']:.1f} | {row['mean_ms']:.2f} |")
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, default=ROOT / "experiments" / "model_variants" / "supermag_fast.onnx")
    p.add_argument("--data", type=Path, default=ROOT / "data" / "robust.npz")
    p.add_argument("--levels", default="0,0.5,0.8,0.9,0.95,1", help="confidence levels, comma-separated")
    p.add_argument("--samples", type=int, default=8, help="prior samples of the 'samples' escalation")
    p.add_argument("--timed", type=int, default=200, help="presses timed per method")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "benchmarks" / "escalation.json")
    a = p.parse_args()
    levels = [float(v) for v in a.levels.split(",")]
    publish(run(a.model, a.data, levels, a.samples, a.timed), a.out, markdown)


if __name__ == "__main__":
    main()
