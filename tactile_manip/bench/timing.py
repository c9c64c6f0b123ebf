"""Timings of one reconstructor: one reading, batches, and the whole pose (reading -> angle, one and two pads).

Each measurement warms up first, then runs until it has ``max_calls`` samples or ``max_seconds`` have
passed (whichever comes first, but at least ``min_calls``), so a 100 ms model does not hold the report up
for minutes while a 1 ms one still gets a stable p99. The number of calls is reported with every figure.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_manip.perception.estimator import TactilePoseEstimator
from tactile_manip.perception.reconstruct import Reconstructor


@dataclass(frozen=True)
class TimingBudget:
    """How long each timing runs.

    Attributes:
        max_calls: single-reading (and pose) calls at most.
        min_calls: calls at least, whatever the time.
        max_seconds: time per measurement after which it stops (once ``min_calls`` are done), s.
        warmup: untimed calls first (session and allocator warm-up).
        batch: readings per batch for the throughput.
        batch_rounds: batches at most for the throughput (at least one, after one untimed batch).
    """

    max_calls: int = 300
    min_calls: int = 20
    max_seconds: float = 4.0
    warmup: int = 5
    batch: int = 64
    batch_rounds: int = 5

    def __post_init__(self) -> None:
        if not (1 <= self.min_calls <= self.max_calls and self.batch >= 1 and self.batch_rounds >= 1):
            raise ValueError(f"TimingBudget: need 1 <= min_calls <= max_calls and batch, batch_rounds >= 1, got {self}")
        if not self.max_seconds > 0 or self.warmup < 0:
            raise ValueError(f"TimingBudget: max_seconds must be > 0 and warmup >= 0, got {self}")


def _timed_calls(call, inputs: np.ndarray, budget: TimingBudget) -> np.ndarray:
    """Latencies in ms of ``call(x)`` over ``inputs`` cycled, within ``budget``."""
    for i in range(budget.warmup):
        call(inputs[i % len(inputs)])
    out: list[float] = []
    start = time.perf_counter()
    while len(out) < budget.max_calls:
        x = inputs[len(out) % len(inputs)]
        t0 = time.perf_counter()
        call(x)
        t1 = time.perf_counter()
        out.append((t1 - t0) * 1e3)
        if len(out) >= budget.min_calls and t1 - start > budget.max_seconds:
            break
    return np.asarray(out)


def single_reading_ms(rec: Reconstructor, readings: np.ndarray, budget: TimingBudget) -> dict[str, Any]:
    """Latency of ``rec.reconstruct`` for one reading (N, R, C, 3 cycled): p50, p99 in ms, and the call count."""
    ms = _timed_calls(rec.reconstruct, readings, budget)
    return {"latency_p50_ms": float(np.percentile(ms, 50)), "latency_p99_ms": float(np.percentile(ms, 99)),
            "latency_calls": int(ms.size)}


def batch_throughput(rec: Reconstructor, readings: np.ndarray, budget: TimingBudget) -> dict[str, Any]:
    """Readings per second of ``rec.reconstruct_batch`` on batches of ``budget.batch`` readings.

    The first batch warms up (a new batch size allocates) and is not counted, unless it alone took longer
    than ``budget.max_seconds``: then it is the only one, and ``warm`` is False in the result.
    """
    reps = -(-budget.batch // len(readings))
    block = np.concatenate([readings] * reps)[: budget.batch]
    seconds: list[float] = []
    start = time.perf_counter()
    while len(seconds) <= budget.batch_rounds:
        t0 = time.perf_counter()
        rec.reconstruct_batch(block)
        seconds.append(time.perf_counter() - t0)
        if time.perf_counter() - start > budget.max_seconds and (len(seconds) >= 2 or seconds[0] > budget.max_seconds):
            break
    timed = seconds[1:] or seconds
    return {"throughput_rps": len(timed) * budget.batch / sum(timed), "batch": budget.batch,
            "batch_rounds": len(timed), "warm": len(seconds) > 1}


def pose_latency_ms(rec: Reconstructor, readings: np.ndarray, budget: TimingBudget) -> dict[str, Any]:
    """Reading -> angle latency per method, ms: :meth:`TactilePoseEstimator.estimate` of one reading
    (reconstruct, post-process, PCA), and :meth:`TactilePoseEstimator.estimate_many` of two pads' readings
    (one batched model run, then the pose of each: the time per pair). ``postprocess_share`` is the part of
    the one-reading time spent after the reconstruction (outlier removal, filter, PCA, confidence).
    """
    estimator = TactilePoseEstimator(rec)
    post_s, total_s = [], []

    def one(x: np.ndarray) -> None:
        timings = estimator.estimate(x).timings_s
        post_s.append(timings.get("pose", 0.0))  # 0 where the angle head answered (no image decoded)
        total_s.append(timings["total"])

    ms = _timed_calls(one, readings, budget)
    timed = slice(budget.warmup, None)
    pairs = np.stack([readings, np.roll(readings, 1, axis=0)], axis=1)  # (N, 2, R, C, 3): two pads' readings
    pair_ms = _timed_calls(estimator.estimate_many, pairs, budget)
    return {"pose_p50_ms": float(np.percentile(ms, 50)), "pose_p99_ms": float(np.percentile(ms, 99)),
            "pose_calls": int(ms.size), "pose_pair_p50_ms": float(np.percentile(pair_ms, 50)),
            "pose_pair_p99_ms": float(np.percentile(pair_ms, 99)), "pose_pair_calls": int(pair_ms.size),
            "postprocess_share": float(sum(post_s[timed]) / sum(total_s[timed]))}
