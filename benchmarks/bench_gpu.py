"""Latency of the reconstruction models in torch on a CUDA GPU: one reading, p50/p99, and batch throughput.

    python -m benchmarks.bench_gpu                                  # untrained compact and paper presets
    python -m benchmarks.bench_gpu --model "paper=runs/paper_gpu/best.pt" --repeats 2000

The paper reports 2.5 ms per reading on an RTX 3090; this is the comparable figure for our presets. A reading
goes in and the image comes out as numpy on the host, so each timing includes both copies (what a control
loop pays). The product path is onnxruntime on the CPU (benchmarks.bench_model); this harness needs torch
with CUDA and a GPU, and says so when either is missing. Latency does not depend on the weights, so presets
without a checkpoint are timed untrained. Prints a markdown table and writes docs/results/benchmarks/gpu.json.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish

PAPER_GPU_MS = 2.5  # SuperMag Sec. IV: one reading on an RTX 3090


def time_checkpoint(path: Path, *, repeats: int, batch: int) -> dict[str, Any]:
    import torch

    from tactile_manip.bench.timing import TimingBudget, batch_throughput, single_reading_ms
    from tactile_manip.learning.cvae.eager import TorchReconstructor
    from tactile_manip.learning.cvae.model import count_parameters

    rec = TorchReconstructor(path, device="cuda")  # each call ends with the copy back: the GPU work is done
    readings = np.random.default_rng(0).normal(0, 150, (repeats,) + rec.input_shape).astype(np.float32)
    budget = TimingBudget(max_calls=repeats, min_calls=repeats, max_seconds=600.0, warmup=50, batch=batch,
                          batch_rounds=20)
    single = single_reading_ms(rec, readings, budget)
    throughput = batch_throughput(rec, readings, budget)
    return {"checkpoint": str(path), "model": rec.name,
            "parameters": count_parameters(rec.graph.model, inference_only=True),
            "gpu": torch.cuda.get_device_name(rec.device), "torch": torch.__version__,
            "p50_ms": single["latency_p50_ms"], "p99_ms": single["latency_p99_ms"],
            "batch": batch, "batch_ms_per_reading": 1e3 / throughput["throughput_rps"]}


def markdown(report: dict[str, Any]) -> str:
    rows = report["results"]
    gpu, version = (rows[0]["gpu"], rows[0]["torch"]) if rows else ("?", "?")
    lines = [f"GPU: {gpu}, torch {version} (eager, float32 weights, torch default precision)", "",
             "| model | parameters | p50 ms | p99 ms | batch-64 ms/reading | p99 within the paper's 2.5 ms |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        within = "yes" if r["p99_ms"] <= PAPER_GPU_MS else "no"
        lines.append(f"| {r['label']} | {r['parameters']:,} | {r['p50_ms']:.2f} | {r['p99_ms']:.2f} | "
                     f"{r['batch_ms_per_reading']:.3f} | {within} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", action="append", default=[], metavar="LABEL=CHECKPOINT.pt")
    p.add_argument("--repeats", type=int, default=1000)
    p.add_argument("--out", default="docs/results/benchmarks/gpu.json")
    args = p.parse_args(argv)
    try:
        import torch
    except ImportError:
        raise SystemExit("bench_gpu needs torch with CUDA: pip install torch (a CUDA build)") from None
    if not torch.cuda.is_available():
        raise SystemExit(f"bench_gpu needs a CUDA GPU; torch {torch.__version__} sees none "
                         "(benchmarks.bench_model times the CPU path)")
    from tactile_manip.learning.cvae.eager import export_untrained

    with tempfile.TemporaryDirectory() as tmp:
        models = [tuple(s.split("=", 1)) for s in args.model]
        if not models:
            for name in ("compact", "paper"):
                export_untrained(name, tmp)
                models.append((f"{name} preset (untrained)", str(Path(tmp) / f"{name}.pt")))
        results = [{"label": label, **time_checkpoint(Path(path), repeats=args.repeats, batch=64)}
                   for label, path in models]
    publish({"machine": machine_info(), "results": results}, args.out, markdown)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
