"""Latency of the reconstruction models on onnxruntime: one reading, p50/p99, and batch throughput.

One reading runs the file's one-reading graph when it has one and runs on one thread
(``perception/one_reading.py``), as the estimator does; the main graph is then timed on the same readings,
interleaved, for comparison.

    python -m benchmarks.bench_model                      # the shipped model and the paper preset
    python -m benchmarks.bench_model --model NAME=PATH.onnx --repeats 2000

Without a trained paper-preset file the harness exports an untrained one (latency does not depend on the
weights). Prints a markdown table and writes docs/results/benchmarks/model.json. It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.perception.reconstruct import OnnxReconstructor, read_metadata

SHIPPED = Path("experiments/model_variants/supermag_fast.onnx")
PREVIOUS = Path("experiments/model_variants/supermag_compact.onnx")  # shipped before it: the accuracy reference
PAPER_RUN = Path("runs/paper/best.pt")
PERIOD_MS = 8.0  # the sensor's 125 Hz frame period


def _untrained(preset: str, folder: Path) -> Path:
    """Export a randomly initialised model of ``preset`` (for timing only)."""
    from tactile_manip.learning.cvae.eager import export_untrained

    return export_untrained(preset, folder)


def time_model(path: Path, *, threads: int, repeats: int, batch: int) -> dict[str, Any]:
    rec = OnnxReconstructor(path, threads=threads)
    main = OnnxReconstructor(path, threads=threads, one_reading_graph=False) if rec.one_reading else None
    rng = np.random.default_rng(0)
    readings = rng.normal(0, 150, (repeats,) + rec.input_shape).astype(np.float32)
    for r in readings[:20]:
        rec.reconstruct(r)
        if main is not None:
            main.reconstruct(r)
    ms, main_ms = [], []
    for r in readings:  # interleaved, so a busy machine slows both alike
        t0 = time.perf_counter()
        rec.reconstruct(r)
        t1 = time.perf_counter()
        if main is not None:
            main.reconstruct(r)
            main_ms.append((time.perf_counter() - t1) * 1e3)
        ms.append((t1 - t0) * 1e3)
    block = readings[:batch]
    t0 = time.perf_counter()
    rounds = max(1, 200 // batch)
    for _ in range(rounds):
        rec.reconstruct_batch(block)
    per_reading = (time.perf_counter() - t0) * 1e3 / (rounds * batch)
    meta = read_metadata(path)
    return {"model": str(path), "preset": meta.get("preset"), "parameters": meta.get("parameters"),
            "file_mb": round(path.stat().st_size / 1e6, 2), "threads": threads, "one_reading_graph": rec.one_reading,
            "p50_ms": float(np.percentile(ms, 50)), "p99_ms": float(np.percentile(ms, 99)),
            "main_graph_p50_ms": float(np.percentile(main_ms, 50)) if main_ms else None,
            "main_graph_p99_ms": float(np.percentile(main_ms, 99)) if main_ms else None,
            "batch": batch, "batch_ms_per_reading": per_reading}


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [f"Machine: {m.get('cpu_model', '?')}, {m.get('usable_cores', '?')} cores, onnxruntime {report['onnxruntime']}",
             "", "| model | preset | parameters | file MB | threads | p50 ms | p99 ms | main graph p50 / p99 ms | "
             "batch-64 ms/reading | p99 within 8 ms period |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in report["results"]:
        main = (f"{r['main_graph_p50_ms']:.2f} / {r['main_graph_p99_ms']:.2f}" if r.get("main_graph_p50_ms")
                else "(main graph only)")
        lines.append(f"| {r['label']} | {r['preset']} | {r['parameters']:,} | {r['file_mb']} | {r['threads']} | "
                     f"{r['p50_ms']:.2f} | {r['p99_ms']:.2f} | {main} | {r['batch_ms_per_reading']:.2f} | "
                     f"{'yes' if r['p99_ms'] < PERIOD_MS else 'no'} |")
    lines += ["", "p50 / p99: one reading as the estimator runs it (the one-reading graph where the file has one, on one "
              "thread); main graph: the same readings through the batch graph, interleaved."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    import onnxruntime

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", action="append", default=[], metavar="LABEL=PATH")
    p.add_argument("--repeats", type=int, default=1000)
    p.add_argument("--threads", type=int, nargs="+", default=[1, os.cpu_count() or 1])
    p.add_argument("--out", default="docs/results/benchmarks/model.json")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        models = [tuple(s.split("=", 1)) for s in args.model]
        if not models:
            models = [("shipped fast", str(SHIPPED)), ("compact (previous)", str(PREVIOUS))]
            paper = PAPER_RUN.with_suffix(".onnx") if PAPER_RUN.with_suffix(".onnx").exists() else None
            models.append(("paper preset", str(paper or _untrained("paper", Path(tmp)))))
        results = [{"label": label, **time_model(Path(path), threads=t, repeats=args.repeats, batch=64)}
                   for label, path in models for t in dict.fromkeys(args.threads)]
    report = {"machine": machine_info(), "onnxruntime": onnxruntime.__version__, "results": results}
    publish(report, args.out, markdown)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
