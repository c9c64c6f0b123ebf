"""Contact estimation: one reading -> ContactState latency on one thread, beside the model's error.

    python -m benchmarks.bench_contact --case spatial=runs/spatial.onnx:data/spatial.npz \\
                                       --case normal=runs/normal.onnx:data/normal.npz

Per case (an exported contact model and the labelled dataset it was trained on), the test split's readings
are fed one at a time, in time order, to ``ContactEstimator.estimate`` (one onnxruntime thread, the context
kept by the estimator as on a live stream), ``--repeats`` passes. Reported: latency p50 / p99 / max of
``estimate`` (input checks, context, model, state), the p99 over readings of each reading's fastest call
(what the machine's jitter does not explain), p50 of the bare ``session.run``; and the error of those same
estimates: RMSE per target, 2-D position RMSE, share within 1 sigma. Prints a markdown table and writes
benchmarks/results/contact.json. It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one thread, as the table says
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402
from tactile_manip.data import load_dataset  # noqa: E402
from tactile_manip.perception.contact import ContactEstimator  # noqa: E402


def bench_case(model_path: str, data_path: str, repeats: int) -> dict[str, Any]:
    """Latency and error of one model on its dataset's test split (see the module docstring)."""
    data = load_dataset(data_path)
    est = ContactEstimator(model_path, threads=1)
    test = data.indices("test")
    times_s = data.extra("time_s") if data.has("time_s") else np.arange(len(data)) * 0.01
    calls = np.empty((repeats, len(test)))
    states = []
    for r in range(repeats):
        est.reset()
        offset = r * (float(times_s.max() - times_s.min()) + 10.0)  # each pass a new stream
        for j, i in enumerate(test):
            reading = data.readings[i]
            t0 = time.perf_counter()
            state = est.estimate(reading, t_s=float(times_s[i]) + offset)
            calls[r, j] = time.perf_counter() - t0
            if r == 0:
                states.append(state)
    window = np.zeros((1, est.context_frames, *est.input_shape), np.float32)
    bare = []
    for _ in range(min(2000, calls.size)):
        t0 = time.perf_counter()
        est.session.run(None, {"field_ut": window})
        bare.append(time.perf_counter() - t0)
    names = list(est.target_names)
    pred = np.array([[s.values[n] for n in names] for s in states])
    sigma = np.array([[s.sigmas[n] for n in names] for s in states])
    true = np.stack([data.target(n)[test] for n in names], 1)
    err = pred - true
    out: dict[str, Any] = {
        "model": model_path, "data": data_path, "readings": int(len(test)), "calls": int(calls.size),
        "p50_ms": 1e3 * float(np.percentile(calls, 50)), "p99_ms": 1e3 * float(np.percentile(calls, 99)),
        "max_ms": 1e3 * float(calls.max()), "p99_of_min_ms": 1e3 * float(np.percentile(calls.min(0), 99)),
        "session_run_p50_ms": 1e3 * float(np.percentile(bare, 50)),
        "rmse": {n: float(np.sqrt(np.mean(err[:, k] ** 2))) for k, n in enumerate(names)},
        "within_1_sigma": float((np.abs(err) <= sigma).mean()), "context_frames": est.context_frames,
        "parameters": est.metadata.get("parameters")}
    if "x_mm" in names and "y_mm" in names:
        out["position_rmse_mm"] = float(np.sqrt(np.mean(err[:, names.index("x_mm")] ** 2 +
                                                        err[:, names.index("y_mm")] ** 2)))
    return out


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [f"ContactEstimator.estimate, one reading, one thread; {m.get('cpu_model', '')}, "
             f"{m.get('usable_cores')} usable cores, load average {m.get('load_average')}", "",
             "| case | p50 ms | p99 ms | max ms | p99 of per-reading min ms | session.run p50 ms | error "
             "| within 1 sigma |",
             "|---|---|---|---|---|---|---|---|"]
    for label, c in report["cases"].items():
        err = ", ".join([*([f"2-D {c['position_rmse_mm']:.3f} mm"] if "position_rmse_mm" in c else []),
                         *(f"{n} {v:.3f}" for n, v in c["rmse"].items() if n not in ("x_mm", "y_mm")
                           or "position_rmse_mm" not in c)])
        lines.append(f"| {label} | {c['p50_ms']:.3f} | {c['p99_ms']:.3f} | {c['max_ms']:.3f} | "
                     f"{c['p99_of_min_ms']:.3f} | {c['session_run_p50_ms']:.3f} | RMSE {err} | "
                     f"{100 * c['within_1_sigma']:.1f} % |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", action="append", required=True, metavar="LABEL=MODEL.onnx:DATA.npz",
                        help="an exported contact model and its labelled dataset (repeatable)")
    parser.add_argument("--repeats", type=int, default=5, help="passes over the test readings")
    parser.add_argument("--out", default="benchmarks/results/contact.json")
    args = parser.parse_args()
    cases = {}
    for spec in args.case:
        label, _, rest = spec.partition("=")
        model, _, data = rest.rpartition(":")
        if not (label and model and data):
            parser.error(f"--case must be LABEL=MODEL.onnx:DATA.npz, got {spec!r}")
        cases[label] = bench_case(model, data, args.repeats)
    report = {"machine": machine_info(), "repeats": args.repeats, "cases": cases}
    publish(report, args.out, markdown)


if __name__ == "__main__":
    main()
