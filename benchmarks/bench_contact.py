"""Contact estimation: one reading -> ContactState latency on one thread, beside the model's error.

    python -m benchmarks.bench_contact --case spatial=runs/spatial.onnx:data/spatial.npz \\
                                       --case normal=runs/normal.onnx:data/normal.npz

Per case (an exported contact model and the labelled dataset it was trained on), the test split's readings
are fed one at a time, in time order, to ``ContactEstimator.estimate`` (one onnxruntime thread, the context
kept by the estimator as on a live stream; without the board's press check, so that the model runs on every
reading), ``--repeats`` passes, each a new stream: back to back (a loop
that does nothing else, its caches warm), or one call per ``--period-ms`` with the thread asleep in between,
as a loop fed by a sensor is (other processes then run on the core and take over its caches). Reported, from
the wall clock of each call (input checks, context, model, state):

- p50 / p99 / max over every call: the honest figure, with whatever the machine's other jobs did to it;
- the p99 of the quietest pass and of the median pass: a pass is a few hundred milliseconds, so a burst of
  other work spoils some passes and leaves others alone;
- the p99 over readings of each reading's fastest call: the cost of the readings themselves, without the
  machine's jitter;
- the calling thread's CPU time per call (p50 / p99): a call that the scheduler preempted waits without
  spending CPU time, so this is what the code costs;
- the share of calls over ``--budget-ms``, the involuntary context switches of the timing thread during the
  passes (each a time slice given to another process, in the middle of a call or between two), and the cores
  other processes kept busy meanwhile;
- p50 of the graph alone as the estimator runs it (input and outputs bound once) and through the plain
  ``session.run`` (a dict in, new arrays out): the rest of a call is Python.

And the error of those same estimates: RMSE per target, 2-D position RMSE, share within 1 sigma. Prints a
markdown table and writes it beside the JSON (default docs/results/contact/latency.json and .md). It
measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one thread, as the table says
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402
from tactile_manip.bench.machine import cpu_counters, other_load  # noqa: E402
from tactile_manip.data import load_dataset  # noqa: E402
from tactile_manip.perception.contact import ContactEstimator  # noqa: E402


def bench_case(model_path: str, data_path: str, repeats: int, budget_ms: float, period_ms: float = 0.0
               ) -> dict[str, Any]:
    """Latency and error of one model on its dataset's test split (see the module docstring)."""
    data = load_dataset(data_path)
    # the model on every reading, as the committed figures were measured: the board's press check would skip
    # the readings within its noise floor (no contact), whose error and cost this measures too
    est = ContactEstimator(model_path, threads=1, press_check=False)
    names = list(est.target_names)
    test = data.indices("test")
    times_s = data.extra("time_s") if data.has("time_s") else np.arange(len(data)) * 0.01
    readings = [np.ascontiguousarray(data.readings[i], np.float32) for i in test]
    t_s = [float(times_s[i]) for i in test]
    wall = np.empty((repeats, len(test)))
    cpu = np.empty((repeats, len(test)))
    pred = np.empty((len(test), len(names)))
    sigma = np.empty((len(test), len(names)))
    before, switches = cpu_counters(), _involuntary_switches()
    tick = time.perf_counter()
    for r in range(repeats):
        est.reset()
        offset = r * (max(t_s) - min(t_s) + 10.0)  # each pass a new stream
        for j in range(len(test)):
            if period_ms > 0:
                tick += 1e-3 * period_ms
                time.sleep(max(0.0, tick - time.perf_counter()))
            c0 = time.thread_time()
            t0 = time.perf_counter()
            state = est.estimate(readings[j], t_s=t_s[j] + offset)
            t1 = time.perf_counter()
            cpu[r, j] = time.thread_time() - c0
            wall[r, j] = t1 - t0
            if r == 0:
                pred[j] = [state.values[n] for n in names]
                sigma[j] = [state.sigmas[n] for n in names]
    switches = _involuntary_switches() - switches
    load = other_load(before, cpu_counters())
    true = np.stack([data.target(n)[test] for n in names], 1)
    err = pred - true
    ms = 1e3 * wall
    pass_p99 = np.sort(np.percentile(ms, 99, axis=1))
    out: dict[str, Any] = {
        "model": model_path, "data": data_path, "readings": int(len(test)), "passes": repeats,
        "calls": int(wall.size), "period_ms": period_ms, "context_frames": est.context_frames,
        "parameters": est.metadata.get("parameters"),
        "p50_ms": float(np.percentile(ms, 50)), "p99_ms": float(np.percentile(ms, 99)), "max_ms": float(ms.max()),
        "p99_quietest_pass_ms": float(pass_p99[0]), "p99_median_pass_ms": float(np.median(pass_p99)),
        "p99_of_min_ms": float(np.percentile(ms.min(0), 99)),
        "cpu_p50_ms": 1e3 * float(np.percentile(cpu, 50)), "cpu_p99_ms": 1e3 * float(np.percentile(cpu, 99)),
        "budget_ms": budget_ms, "over_budget_share": float((ms > budget_ms).mean()),
        "involuntary_switches": switches, "other_load": load,
        **_graph_alone(est, min(2000, wall.size)),
        "rmse": {n: float(np.sqrt(np.mean(err[:, k] ** 2))) for k, n in enumerate(names)},
        "within_1_sigma": float((np.abs(err) <= sigma).mean())}
    if "x_mm" in names and "y_mm" in names:
        out["position_rmse_mm"] = float(np.sqrt(np.mean(err[:, names.index("x_mm")] ** 2 +
                                                        err[:, names.index("y_mm")] ** 2)))
    return out


def _involuntary_switches() -> int:
    """Times the scheduler took the core from this thread (Linux: the thread's own count), -1 where unknown."""
    who = getattr(resource, "RUSAGE_THREAD", resource.RUSAGE_SELF)
    try:
        return int(resource.getrusage(who).ru_nivcsw)
    except (OSError, ValueError):
        return -1


def _graph_alone(est: ContactEstimator, calls: int) -> dict[str, float]:
    """p50 (ms) of the model on a zero window: bound as the estimator binds it, and through ``session.run``."""
    import onnxruntime as ort

    window = np.zeros((1, est.context_frames, *est.input_shape), np.float32)
    mean, sigma = (np.zeros((1, len(est.target_names)), np.float32) for _ in range(2))
    binding = est.session.io_binding()
    binding.bind_ortvalue_input("field_ut", ort.OrtValue.ortvalue_from_numpy(window))
    binding.bind_ortvalue_output("mean", ort.OrtValue.ortvalue_from_numpy(mean))
    binding.bind_ortvalue_output("sigma", ort.OrtValue.ortvalue_from_numpy(sigma))
    bound, plain = np.empty(calls), np.empty(calls)
    for i in range(calls):  # interleaved: a busy moment slows both alike
        t0 = time.perf_counter()
        est.session.run_with_iobinding(binding)
        t1 = time.perf_counter()
        est.session.run(None, {"field_ut": window})
        t2 = time.perf_counter()
        bound[i], plain[i] = t1 - t0, t2 - t1
    return {"graph_p50_ms": 1e3 * float(np.median(bound)), "session_run_p50_ms": 1e3 * float(np.median(plain))}


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [f"ContactEstimator.estimate, one reading, one thread; {m.get('cpu_model', '')}, "
             f"{m.get('usable_cores')} usable cores, load average {m.get('load_average')}; "
             f"{report['repeats']} passes per case, "
             + (f"one call per {report['period_ms']:g} ms" if report.get("period_ms") else "calls back to back"),
             "",
             "| case | frames | p50 ms | p99 ms | max ms | p99 quietest / median pass ms | p99 of per-reading min ms "
             "| CPU p50 / p99 ms | calls over budget | involuntary switches | other cores busy | graph p50 ms (bound / run) "
             "| error | within 1 sigma |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for label, c in report["cases"].items():
        err = ", ".join([*([f"2-D {c['position_rmse_mm']:.3f} mm"] if "position_rmse_mm" in c else []),
                         *(f"{n} {v:.3f}" for n, v in c["rmse"].items() if n not in ("x_mm", "y_mm")
                           or "position_rmse_mm" not in c)])
        busy = c["other_load"]["other_processes_cores"] if c.get("other_load") else "-"
        lines.append(f"| {label} | {c['context_frames']} | {c['p50_ms']:.3f} | {c['p99_ms']:.3f} | {c['max_ms']:.3f} | "
                     f"{c['p99_quietest_pass_ms']:.3f} / {c['p99_median_pass_ms']:.3f} | {c['p99_of_min_ms']:.3f} | "
                     f"{c['cpu_p50_ms']:.3f} / {c['cpu_p99_ms']:.3f} | "
                     f"{100 * c['over_budget_share']:.2f} % > {c['budget_ms']:g} ms | "
                     f"{c['involuntary_switches']} in {c['calls']} calls | {busy} | "
                     f"{c['graph_p50_ms']:.3f} / {c['session_run_p50_ms']:.3f} | RMSE {err} | "
                     f"{100 * c['within_1_sigma']:.1f} % |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", action="append", required=True, metavar="LABEL=MODEL.onnx:DATA.npz",
                        help="an exported contact model and its labelled dataset (repeatable)")
    parser.add_argument("--repeats", type=int, default=10, help="passes over the test readings")
    parser.add_argument("--budget-ms", type=float, default=0.2, help="report the share of calls slower than this")
    parser.add_argument("--period-ms", type=float, default=0.0,
                        help="one call per period, asleep in between, as a sensor loop (0: back to back)")
    parser.add_argument("--out", default="docs/results/contact/latency.json",
                        help="JSON report; the markdown table goes beside it (.md)")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats must be >= 1, got {args.repeats}")
    if not args.period_ms >= 0:
        parser.error(f"--period-ms must be >= 0, got {args.period_ms}")
    cases = {}
    for spec in args.case:
        label, _, rest = spec.partition("=")
        model, _, data = rest.rpartition(":")
        if not (label and model and data):
            parser.error(f"--case must be LABEL=MODEL.onnx:DATA.npz, got {spec!r}")
        cases[label] = bench_case(model, data, args.repeats, args.budget_ms, args.period_ms)
    report = {"machine": machine_info(), "repeats": args.repeats, "period_ms": args.period_ms, "cases": cases}
    publish(report, args.out, markdown)
    Path(args.out).with_suffix(".md").write_text(markdown(report) + "\n")


if __name__ == "__main__":
    main()
