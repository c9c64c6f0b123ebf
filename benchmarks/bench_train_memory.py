"""Peak memory of ``tactile-manip train`` on a sharded dataset of 1x and 10x the default size.

Run from the repository root (see ``benchmarks/README.md``)::

    python -m benchmarks.bench_train_memory [--samples 7290] [--factor 10] [--minutes 1] [--in-memory]

The 1x dataset has the default dataset's size (7,290 presses, ``configs/dataset/supermag.toml``), the 10x one ten
times that. Simulating 80,000 presses takes hours on two cores, so both are made of the presses of one small
simulated base (``--base-scale`` of the config, 146 presses at 0.02) repeated in order: training reads, holds and
batches them as it would new presses, and the memory it needs depends on their count and size, not on their
values. Each dataset is written as shards (``--shard-size``). Each run is ``tactile-manip train`` in a child
process for ``--minutes`` of training (the epoch is cut there) and one full validation pass; the child's peak
resident memory comes from ``os.wait4`` (``ru_maxrss``). ``--in-memory`` adds the 1x dataset as one file, which
train holds whole, for comparison. Datasets are kept in ``--work`` for reruns. It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.data import PairedDataset, ShardedDataset, ShardWriter, load_dataset, save_dataset
from tactile_manip.sim.dataset import generate, load_dataset_config

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CONFIG = ROOT / "configs" / "dataset" / "supermag.toml"
DEFAULT_TRAIN = ROOT / "configs" / "train" / "fast.toml"
DEFAULT_OUT = ROOT / "docs" / "results" / "benchmarks" / "train_memory.json"
DEFAULT_SAMPLES = 7290   # presses in configs/dataset/supermag.toml at scale 1


def base_dataset(work: Path, config: Path, scale: float, workers: int) -> PairedDataset:
    """The simulated presses the datasets repeat (made once, then read from ``work``)."""
    path = work / f"base_{scale:g}.npz"
    if not path.is_file():
        save_dataset(path, generate(load_dataset_config(config).scaled(scale), workers=workers))
    return load_dataset(path)


def repeated(base: PairedDataset, start: int, stop: int) -> PairedDataset:
    """Samples ``start .. stop - 1`` of ``base`` repeated without end."""
    return base.subset(np.arange(start, stop) % len(base))


def shard_folder(work: Path, base: PairedDataset, samples: int, shard_size: int) -> Path:
    """``samples`` presses of ``base`` repeated, as a shard folder (written one shard at a time)."""
    path = work / f"repeated_{samples}_{shard_size}"
    if path.is_dir():
        return path
    with ShardWriter(path, shard_size=shard_size) as writer:
        for start in range(0, samples, shard_size):
            writer.write(repeated(base, start, min(start + shard_size, samples)))
        return writer.finish({"source": "benchmarks/bench_train_memory.py", "repeats": base.fingerprint(),
                              "base_samples": len(base)})


def one_file(work: Path, base: PairedDataset, samples: int) -> Path:
    path = work / f"repeated_{samples}.npz"
    if not path.is_file():
        save_dataset(path, repeated(base, 0, samples))
    return path


def train_peak(data: Path, config: Path, out: Path, minutes: float, threads: int) -> dict[str, Any]:
    """Run ``tactile-manip train`` in a child process; its peak resident memory and what it did."""
    cmd = [sys.executable, "-m", "tactile_manip", "train", "--config", str(config), "--data", str(data),
           "--out", str(out), "--force", "--epochs", "1", "--max-minutes", str(minutes), "--threads", str(threads)]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    t0 = time.perf_counter()
    with open(out.with_suffix(".log"), "w") as log:
        child = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    if child.returncode != 0:
        raise RuntimeError(f"train failed ({child.returncode}); see {out.with_suffix('.log')}")
    history = json.loads((out / "history.json").read_text())
    row = history["history"][-1]
    return {"peak_rss_mb": usage.ru_maxrss / 1024, "wall_s": wall, "steps": row["batches"],
            "epoch_fraction": row["epoch_fraction"], "val_psnr": row["val_psnr"],
            "fingerprint": history["data_fingerprint"]}


def _shown(path: Path) -> str:
    """``path`` relative to the repository when it is inside it (the report does not name this checkout)."""
    path = path.resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def markdown(report: dict[str, Any]) -> str:
    m, s = report["machine"], report["settings"]
    lines = [f"Machine: {m['cpu_model']}, {m['usable_cores']}/{m['cpu_count']} cores, Python {m['python']}, "
             f"code {m['code_version']}", "",
             f"### train peak memory ({s['train_config']}, {s['minutes']:g} min of steps then one validation pass, "
             f"{s['threads']} thread(s); shards of {s['shard_size']})",
             "| dataset | form | presses | shards | on disk MB | steps | peak RSS MB | vs 1x sharded |",
             "|---|---|---|---|---|---|---|---|"]
    first = report["runs"][0]["peak_rss_mb"]
    for r in report["runs"]:
        lines.append(f"| {r['name']} | {r['form']} | {r['samples']} | {r['shards']} | {r['disk_mb']:.0f} | "
                     f"{r['steps']} | {r['peak_rss_mb']:.0f} | {r['peak_rss_mb'] / first:.2f} |")
    lines += ["", f"{s['factor']}x / 1x peak memory (sharded): **{report['ratio_10x_1x']:.2f}** (target <= 1.5)"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench_train_memory", description=__doc__.splitlines()[0])
    p.add_argument("--samples", type=int, default=DEFAULT_SAMPLES, help="presses of the 1x dataset")
    p.add_argument("--factor", type=int, default=10, help="size of the large dataset, in multiples of --samples")
    p.add_argument("--base-scale", type=float, default=0.02, help="scale of the simulated base (of --config)")
    p.add_argument("--config", type=Path, default=DEFAULT_CONFIG, help="dataset config of the base")
    p.add_argument("--train-config", type=Path, default=DEFAULT_TRAIN, help="training config")
    p.add_argument("--shard-size", type=int, default=512, help="presses per shard")
    p.add_argument("--minutes", type=float, default=1.0, help="minutes of training steps per run")
    p.add_argument("--threads", type=int, default=1, help="torch threads of the training process")
    p.add_argument("--workers", type=int, default=1, help="simulation workers for the base")
    p.add_argument("--in-memory", action="store_true", help="also train on the 1x dataset as one file")
    p.add_argument("--work", type=Path, default=Path("/tmp/tactile_manip_bench_train_memory"),
                   help="folder for the datasets and runs (kept for reruns)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON report path")
    args = p.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    base = base_dataset(args.work, args.config, args.base_scale, args.workers)
    datasets = [("1x", "sharded", shard_folder(args.work, base, args.samples, args.shard_size)),
                (f"{args.factor}x", "sharded",
                 shard_folder(args.work, base, args.factor * args.samples, args.shard_size))]
    if args.in_memory:
        datasets.append(("1x", "one file", one_file(args.work, base, args.samples)))
    runs = []
    for name, form, path in datasets:
        sharded = form == "sharded"
        files = list(path.iterdir()) if sharded else [path]
        result = train_peak(path, args.train_config, args.work / f"run_{name}_{form.replace(' ', '_')}",
                            args.minutes, args.threads)
        runs.append({"name": name, "form": form, "path": str(path),
                     "samples": len(ShardedDataset(path)) if sharded else len(load_dataset(path)),
                     "shards": ShardedDataset(path).shard_count if sharded else 1,
                     "disk_mb": sum(f.stat().st_size for f in files) / 1e6, **result})
        print(f"{name} {form}: peak {result['peak_rss_mb']:.0f} MB, {result['steps']} steps", flush=True)
    report = {"machine": machine_info(),
              "settings": {"samples": args.samples, "factor": args.factor, "base_scale": args.base_scale,
                           "base_samples": len(base), "config": _shown(args.config),
                           "train_config": _shown(args.train_config), "shard_size": args.shard_size,
                           "minutes": args.minutes, "threads": args.threads},
              "runs": runs, "ratio_10x_1x": runs[1]["peak_rss_mb"] / runs[0]["peak_rss_mb"]}
    publish(report, args.out, markdown)
    return 0


if __name__ == "__main__":
    sys.exit(main())
