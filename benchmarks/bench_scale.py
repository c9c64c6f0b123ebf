"""Scaling benchmark: simulated presses per second on the local process pool and on Ray, by worker count.

Run from the repository root (needs the ``ray`` extra)::

    python -m benchmarks.bench_scale [--scale 0.02] [--workers 1 2] [--two-node] [--out docs/results/benchmarks/scale.json]

For each worker count it generates the same dataset with ``generate`` (a process pool) and with
``generate_on_ray`` (a private Ray instance of that many CPUs), checks that both give the same fingerprint, and
reports presses per second with and without Ray's start-up. ``--two-node`` also starts a two-node cluster on this
machine's loopback (a head and a second node of one CPU each) and runs against it. It measures; it asserts only
that every run produced the same dataset.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks._common import machine_info, publish
from tactile_manip.cluster.connect import ray_session
from tactile_manip.cluster.simulate import DEFAULT_BLOCK_SIZE, generate_on_ray
from tactile_manip.sim.dataset import generate, load_dataset_config

ROOT = Path(__file__).resolve().parents[1]
PORT = 6397
# Ray replaces a node address of 127.0.0.1 by the machine's network address, except in its single-machine mode,
# which refuses a second node. The second node of the loopback test cluster is therefore started through this
# small launcher, which keeps the address it is given. Benchmark-only: the package never patches Ray.
_LOOPBACK_NODE = """
import sys
import ray._private.services as services
services.resolve_ip_for_localhost = lambda host: host
services.get_node_ip_address = lambda address=None: "127.0.0.1"
from ray.scripts.scripts import main
sys.argv[0] = "ray"
main()
"""


def _timed(fn) -> tuple[Any, float]:
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _ray_start_s(workers: int) -> float:
    def start_stop():
        with ray_session(None, num_cpus=workers):
            pass

    return _timed(start_stop)[1]


def _row(kind: str, workers: int, presses: int, seconds: float, start_s: float, fingerprint: str) -> dict:
    work_s = max(seconds - start_s, 1e-9)
    return {"backend": kind, "workers": workers, "presses": presses, "seconds": round(seconds, 2),
            "start_s": round(start_s, 2), "presses_per_s": round(presses / seconds, 2),
            "presses_per_s_after_start": round(presses / work_s, 2), "fingerprint": fingerprint}


def _two_node(cfg, tmp: Path, block_size: int) -> dict:
    env = dict(os.environ, RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER="0")
    # the joining node: the cluster mode (the launcher keeps its loopback address) and the head's token
    node_env = dict(os.environ, RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER="1", RAY_AUTH_MODE="token")
    ray_cli = [sys.executable, "-m", "ray.scripts.scripts"]
    common = ["--node-ip-address=127.0.0.1", "--num-cpus=1", "--disable-usage-stats"]
    subprocess.run([*ray_cli, "start", "--head", f"--port={PORT}", "--include-dashboard=false", *common],
                   env=env, check=True, capture_output=True)
    try:
        joined = subprocess.run([sys.executable, "-c", _LOOPBACK_NODE, "start", f"--address=127.0.0.1:{PORT}",
                                 *common], env=node_env, capture_output=True, text=True)
        if joined.returncode:
            raise SystemExit(f"the second node did not start: {joined.stderr.strip().splitlines()[-1:]}")
        data, seconds = _timed(lambda: generate_on_ray(cfg, tmp / "two_node.npz", address=f"127.0.0.1:{PORT}",
                                                       block_size=block_size))
        return _row("ray, 2 nodes x 1 CPU", 2, len(data), seconds, 0.0, data.fingerprint())
    finally:
        subprocess.run([*ray_cli, "stop", "--force"], env=env, capture_output=True)


def run(args: argparse.Namespace) -> dict:
    cfg = load_dataset_config(ROOT / "configs/dataset/supermag.toml").scaled(args.scale)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for w in args.workers:
            data, seconds = _timed(lambda: generate(cfg, workers=w))
            rows.append(_row("process pool", w, len(data), seconds, 0.0, data.fingerprint()))
            start_s = _ray_start_s(w)
            data, seconds = _timed(lambda: generate_on_ray(cfg, Path(tmp) / f"ray{w}.npz", num_cpus=w,
                                                           block_size=args.block_size))
            rows.append(_row("ray, local", w, len(data), seconds, start_s, data.fingerprint()))
        if args.two_node:
            rows.append(_two_node(cfg, Path(tmp), args.block_size))
    prints = {r["fingerprint"] for r in rows}
    if len(prints) != 1:
        raise SystemExit(f"runs disagree: fingerprints {sorted(prints)}")
    pool = {r["workers"]: r["presses_per_s"] for r in rows if r["backend"] == "process pool"}
    for r in rows:
        if r["workers"] in pool and r["backend"] != "process pool":
            r["vs_pool"] = round(r["presses_per_s_after_start"] / pool[r["workers"]] - 1.0, 3)
    return {"machine": machine_info(), "scale": args.scale, "block_size": args.block_size, "rows": rows}


def markdown(report: dict) -> str:
    lines = [f"Presses per second, `configs/dataset/supermag.toml` x {report['scale']} "
             f"({report['rows'][0]['presses']} presses, blocks of {report['block_size']}), same fingerprint in every run",
             "", "| backend | workers | seconds | Ray start (s) | presses/s | presses/s after start | vs pool |",
             "|---|---|---|---|---|---|---|"]
    for r in report["rows"]:
        vs = f"{100 * r['vs_pool']:+.1f} %" if "vs_pool" in r else ""
        lines.append(f"| {r['backend']} | {r['workers']} | {r['seconds']} | {r['start_s']} | {r['presses_per_s']} | "
                     f"{r['presses_per_s_after_start']} | {vs} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scale", type=float, default=0.02, help="dataset scale (0.02: 152 presses)")
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--block-size", type=int, default=DEFAULT_BLOCK_SIZE)
    p.add_argument("--two-node", action="store_true", help="also run on a two-node cluster on loopback")
    p.add_argument("--out", default="docs/results/benchmarks/scale.json")
    args = p.parse_args(argv)
    publish(run(args), args.out, markdown)


if __name__ == "__main__":
    main()
