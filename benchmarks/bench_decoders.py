"""Where the network's time goes, node by node, and what decoder candidates would cost (untrained, timed only).

    python -m benchmarks.bench_decoders                  # the shipped model and every
                                                         # experiments/decoder_candidates/decoder_*.toml
    python -m benchmarks.bench_decoders --config experiments/decoder_candidates/decoder_s4.toml --rounds 3

1. onnxruntime's profiler on the shipped model (one thread, ``--profile-calls`` readings): the median time of
   every node, summed by operator type and listed for the slowest nodes.
2. Each candidate training config exported untrained (latency does not depend on the weights) and timed with
   the shipped model through ``OnnxReconstructor.reconstruct``, one reading at a time on one thread, the
   models in a shuffled order per reading so a busy machine slows all of them alike: wall p50 / p99 and the
   calling thread's CPU time p50; and each candidate's own node profile by operator type.

Writes docs/results/benchmarks/decoders.json and prints markdown tables. No accuracy here: an untrained model's
images say nothing; train a candidate (``tactile-manip train --config ...``) and ``tactile-manip evaluate`` it.
"""

from __future__ import annotations

import argparse
import collections
import glob
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402
from benchmarks.bench_pose import rod_readings  # noqa: E402
from tactile_manip.perception.onnx_session import session_options  # noqa: E402
from tactile_manip.perception.reconstruct import OnnxReconstructor, read_metadata  # noqa: E402

SHIPPED = "experiments/model_variants/supermag_fast.onnx"


def node_profile(path: str | Path, readings: np.ndarray, folder: Path) -> dict[str, Any]:
    """Median time per node over ``readings`` (one at a time, one thread), summed by operator type, ms."""
    import onnxruntime as ort

    opts = session_options(ort, threads=1)
    opts.enable_profiling = True
    opts.profile_file_prefix = str(folder / Path(path).stem)
    session = ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])
    latent = int(read_metadata(path)["noise"]["shape"][2])
    eps = np.zeros((1, 1, latent), np.float32)
    for f in readings:
        session.run(None, {"field_ut": f[None].astype(np.float32), "eps": eps})
    events = json.loads(Path(session.end_profiling()).read_text())
    times, ops = collections.defaultdict(list), {}
    for e in events:
        if e.get("cat") == "Node" and e["name"].endswith("_kernel_time"):
            name = e["name"][: -len("_kernel_time")]
            times[name].append(e["dur"] / 1e3)
            ops[name] = e["args"].get("op_name", "?")
    median = {n: float(np.median(v)) for n, v in times.items()}
    by_op = collections.Counter()
    for n, ms in median.items():
        by_op[ops[n]] += ms
    slowest = sorted(median.items(), key=lambda kv: -kv[1])[:12]
    return {"nodes": len(median), "sum_ms": float(sum(median.values())),
            "by_op_ms": dict(by_op.most_common()),
            "slowest": [{"node": n, "op": ops[n], "ms": ms} for n, ms in slowest]}


def interleaved_latency(models: dict[str, Path], readings: np.ndarray, rounds: int) -> dict[str, Any]:
    recs = {name: OnnxReconstructor(path, threads=1) for name, path in models.items()}
    for rec in recs.values():
        for f in readings[:5]:
            rec.reconstruct(f)
    wall = {n: [] for n in recs}
    cpu = {n: [] for n in recs}
    rng, names = np.random.default_rng(0), list(recs)
    for _ in range(rounds):
        for f in readings:
            for name in rng.permutation(names):
                t0, c0 = time.perf_counter(), time.thread_time()
                recs[name].reconstruct(f)
                c1, t1 = time.thread_time(), time.perf_counter()
                wall[name].append((t1 - t0) * 1e3)
                cpu[name].append((c1 - c0) * 1e3)
    return {n: {"p50_ms": float(np.percentile(wall[n], 50)), "p99_ms": float(np.percentile(wall[n], 99)),
                "cpu_p50_ms": float(np.percentile(cpu[n], 50)), "calls": len(wall[n]),
                "parameters": read_metadata(models[n]).get("parameters")} for n in recs}


def markdown(report: dict[str, Any]) -> str:
    m, prof = report["machine"], report["profiles"]
    base = report["latency"]["shipped"]["cpu_p50_ms"]
    lines = [f"Decoder candidates, one reading, one thread; {m['cpu_model']}, {m['usable_cores']} cores, load "
             f"average {m.get('load_average')}. Candidates are untrained exports (latency only).", "",
             "| model | params | wall p50 ms | wall p99 ms | thread CPU p50 ms | CPU vs shipped | "
             "profiled node sum ms |",
             "|---|---|---|---|---|---|---|"]
    for name, r in report["latency"].items():
        params = "-" if r["parameters"] is None else f"{r['parameters'] / 1e6:.2f} M"
        lines.append(f"| {name} | {params} | {r['p50_ms']:.2f} | {r['p99_ms']:.2f} | {r['cpu_p50_ms']:.2f} | "
                     f"{r['cpu_p50_ms'] / base - 1:+.0%} | {prof[name]['sum_ms']:.2f} |")
    shipped_ops = prof["shipped"]["by_op_ms"]
    ops = sorted({op for p in prof.values() for op in p["by_op_ms"]}, key=lambda o: -shipped_ops.get(o, 0.0))
    lines += ["", "Node time by operator type (median per node, summed), ms:", "",
              "| op | " + " | ".join(prof) + " |", "|---" * (len(prof) + 1) + "|"]
    for op in ops[:14]:
        lines.append(f"| {op} | " + " | ".join(f"{p['by_op_ms'].get(op, 0.0):.3f}" for p in prof.values()) + " |")
    lines += ["", "Slowest nodes of the shipped model:", "", "| node | op | ms |", "|---|---|---|"]
    lines += [f"| {s['node']} | {s['op']} | {s['ms']:.3f} |" for s in prof["shipped"]["slowest"]]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", action="append", default=[], help="candidate training config (repeatable; "
                        "default: experiments/decoder_candidates/decoder_*.toml)")
    parser.add_argument("--readings", type=int, default=120)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--profile-calls", type=int, default=200)
    parser.add_argument("--out", default="docs/results/benchmarks/decoders.json")
    args = parser.parse_args()
    from tactile_manip.learning.cvae.eager import export_untrained

    configs = args.config or sorted(glob.glob("experiments/decoder_candidates/decoder_*.toml"))
    fields, _ = rod_readings(args.readings, 0)
    with tempfile.TemporaryDirectory(prefix="bench-decoders-") as tmp:
        models = {"shipped": Path(SHIPPED)} | {Path(c).stem: export_untrained(c, Path(tmp) / "models") for c in configs}
        profiles = {n: node_profile(p, fields[: args.profile_calls], Path(tmp)) for n, p in models.items()}
        latency = interleaved_latency(models, fields, args.rounds)
    report = {"machine": machine_info(), "configs": configs, "latency": latency, "profiles": profiles}
    publish(report, args.out, markdown)


if __name__ == "__main__":
    main()
