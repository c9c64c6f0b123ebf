"""Shared pieces of the benchmark harnesses: the machine description, the report writer, and the training loop
of the small reference networks some benchmarks fit (torch, imported only there)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tactile_manip.bench.machine import machine_info

__all__ = ["fit_best_mse", "machine_info", "publish"]


def publish(report: dict[str, Any], out: str | Path, markdown: Callable[[dict[str, Any]], str]) -> None:
    """Print the report's markdown table and write it as JSON to ``out``."""
    print(markdown(report))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"\nwrote {out}")


def fit_best_mse(net: Any, opt: Any, sched: Any, x: Any, y: Any, train: Any, val: Any, *, epochs: int,
                 batch_size: int, gen: Any = None) -> int:
    """Train ``net`` on the mean-squared error of ``y[train]`` from ``x[train]`` (torch tensors; ``train`` and
    ``val`` row indices or boolean masks), one scheduler step per epoch; load the weights of the epoch with the
    lowest validation error and return that epoch (1-based)."""
    import numpy as np
    import torch

    def rows(index: Any) -> torch.Tensor:
        index = np.asarray(index)
        return torch.from_numpy(np.flatnonzero(index) if index.dtype == bool else index.astype(np.int64))

    tr, va = rows(train), rows(val)
    best = (float("inf"), 0, None)
    for epoch in range(1, epochs + 1):
        net.train()
        for batch in tr[torch.randperm(len(tr), generator=gen)].split(batch_size):
            loss = ((net(x[batch]) - y[batch]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        sched.step()
        net.eval()
        with torch.no_grad():
            val_mse = float(((net(x[va]) - y[va]) ** 2).mean())
        if val_mse < best[0]:
            best = (val_mse, epoch, {k: v.clone() for k, v in net.state_dict().items()})
    net.load_state_dict(best[2])
    return best[1]
