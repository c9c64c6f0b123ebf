"""``simulate --ray``: a dataset's samples as blocks of per-sample seeds, run as Ray tasks.

Each block is :func:`tactile_manip.sim.dataset.simulate_block` on a Ray worker; every sample draws from its own
seed, so the assembled dataset (fingerprint included) equals the local run's. A block whose worker dies is run
again by Ray (``max_retries``); finished blocks are kept in ``<output>.blocks/`` until the output is written, so
an interrupted run started again with the same command does only the blocks that are left.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tactile_manip.cluster.blocks import BlockStore, run_key
from tactile_manip.cluster.connect import cluster_cpus, ray_session
from tactile_manip.config import to_dict
from tactile_manip.data import PairedDataset
from tactile_manip.sim.dataset import DatasetConfig, assemble, sample_count, simulate_block

MAX_RETRIES = 3          # Ray re-runs a block this often when its worker process dies
DEFAULT_BLOCK_SIZE = 32  # samples per task: ~1.5 s of work at ~50 ms a press, small next to Ray's per-task cost


def block_bounds(total: int, block_size: int) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` covering ``0 .. total - 1`` in blocks of ``block_size`` (the last may be short)."""
    if block_size < 1:
        raise ValueError(f"--block-size must be >= 1, got {block_size}")
    return [(s, min(s + block_size, total)) for s in range(0, total, block_size)]


def generate_on_ray(cfg: DatasetConfig, output: str | Path, *, address: str | None = None,
                    num_cpus: int | None = None, block_size: int = DEFAULT_BLOCK_SIZE,
                    progress: Callable[[int], None] | None = None) -> PairedDataset:
    """Simulate every sample of ``cfg`` on Ray; the dataset equals :func:`~tactile_manip.sim.dataset.generate`'s.

    Args:
        cfg: the dataset config.
        output: the dataset file the caller will write; finished blocks are kept beside it until then.
        address: ``None``/"local" (a private instance on this machine), "auto" or "HOST:PORT".
        num_cpus: CPUs of a private instance (None: all).
        block_size: samples per Ray task.
        progress: called with the number of samples finished since the last call (blocks found on disk too).

    Raises:
        ClusterError: the cluster cannot be reached or used, or the block folder belongs to another run.
    """
    bounds = block_bounds(sample_count(cfg), block_size)
    store = BlockStore(output, run_key(to_dict(cfg), block_size))
    done = store.open()
    todo = [(a, b) for a, b in bounds if done.get(a) != b]
    if progress and len(todo) < len(bounds):
        progress(sum(b - a for a, b in bounds) - sum(b - a for a, b in todo))
    start = time.perf_counter()
    workers = 0
    if todo:
        with ray_session(address, num_cpus=num_cpus) as ray:
            workers = cluster_cpus(ray)
            _run_blocks(ray, cfg, todo, store, progress)
    results: list[dict[str, Any]] = []
    for a, b in bounds:
        results += store.load(a, b)
    data = assemble(cfg, results, seconds=time.perf_counter() - start, workers=workers)
    data.provenance["ray"] = {"address": address or "local", "block_size": block_size,
                              "blocks": len(bounds), "blocks_resumed": len(bounds) - len(todo)}
    return data


def _run_blocks(ray: Any, cfg: DatasetConfig, todo: list[tuple[int, int]], store: BlockStore,
                progress: Callable[[int], None] | None) -> None:
    task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(simulate_block)
    cfg_ref = ray.put(cfg)
    pending = {task.remote(cfg_ref, a, b): (a, b) for a, b in todo}
    try:
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            a, b = pending.pop(ready[0])
            store.save(a, b, ray.get(ready[0]))
            if progress:
                progress(b - a)
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
