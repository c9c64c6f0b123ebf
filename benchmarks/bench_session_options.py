"""onnxruntime session options for one reading on one thread, each measured against the others, interleaved.

    python -m benchmarks.bench_session_options                    # the shipped model, 2 rounds of 300 readings
    python -m benchmarks.bench_session_options --model runs/x/model.onnx --rounds 4

Variants of one model: the reconstructor's settings (:func:`~tactile_manip.perception.onnx_session.session_options`)
through ``session.run`` with fresh arrays; then one setting changed at a time (graph optimisation basic /
extended, memory patterns off, spinning off, parallel execution, the batch and sample dimensions fixed to 1 in
an in-memory copy of the graph, io_binding with buffers bound once); and ``OnnxReconstructor.reconstruct``
as users call it. Every variant runs each reading in turn (in a shuffled order per reading), so a busy
machine slows all of them alike. Per variant: wall-clock p50 / p99 and the calling thread's CPU time p50
(less sensitive to other processes than the wall clock). Writes docs/results/benchmarks/session_options.json; it
measures, it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from collections.abc import Callable
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402
from benchmarks.bench_pose import rod_readings  # noqa: E402
from tactile_manip.perception.onnx_session import session_options  # noqa: E402
from tactile_manip.perception.reconstruct import OnnxReconstructor  # noqa: E402


class OneReadingBinding:
    """One reading (1, R, C, 3) through ``session`` with buffers bound once.

    Args:
        session: an ``onnxruntime.InferenceSession`` of an exported model (inputs ``field_ut``, ``eps``;
            outputs ``depth_mm``, ``spread_mm``).
        input_shape: (R, C, 3) of a reading.
        output_hw: (H, W) of the depth image.
        samples: K prior samples per reading; latent: Z.

    :meth:`run` is serialised by a lock: the buffers are shared, so two threads must not fill them at once.
    """

    def __init__(self, session: Any, *, input_shape: tuple[int, ...], output_hw: tuple[int, int], samples: int,
                 latent: int) -> None:
        import onnxruntime as ort

        self._field = np.zeros((1, *input_shape), np.float32)
        self._eps = np.zeros((1, samples, latent), np.float32)
        self._depth = np.empty((1, *output_hw), np.float32)
        self._spread = np.empty((1, *output_hw), np.float32)
        self._session, self._lock = session, threading.Lock()
        self._binding = session.io_binding()
        self._binding.bind_cpu_input("field_ut", self._field)
        self._binding.bind_cpu_input("eps", self._eps)
        # OrtValues over our arrays: onnxruntime writes into them (the arrays stay referenced by self)
        for name, buf in (("depth_mm", self._depth), ("spread_mm", self._spread)):
            self._binding.bind_ortvalue_output(name, ort.OrtValue.ortvalue_from_numpy(buf))

    def run(self, field: np.ndarray, eps: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """``field`` (R, C, 3) float32 and ``eps`` (K, Z) -> depth (H, W) and spread (H, W) as fresh arrays
        (the caller may keep them). ``eps=None`` (K = 1 only): the zero noise, the prior mean, and no spread.
        """
        with self._lock:
            self._field[0] = field
            if eps is None:
                self._eps.fill(0.0)
            else:
                self._eps[0] = eps
            self._session.run_with_iobinding(self._binding)
            return self._depth[0].copy(), (None if eps is None else self._spread[0].copy())


def fixed_batch_graph(path: str) -> bytes:
    """The model with its batch and sample dimensions fixed to 1 (static shapes for one reading), serialised."""
    import onnx

    model = onnx.load(path)
    for value in list(model.graph.input) + list(model.graph.output):
        dims = value.type.tensor_type.shape.dim
        dims[0].dim_value = 1
        if value.name == "eps":
            dims[1].dim_value = 1
    return model.SerializeToString()


def variants(path: str) -> dict[str, Callable[[np.ndarray], Any]]:
    """Name -> a call on one float32 reading (R, C, 3)."""
    import onnxruntime as ort

    rec = OnnxReconstructor(path, threads=1)
    eps = np.zeros((1, 1, rec.latent), np.float32)
    level = ort.GraphOptimizationLevel

    def session(model: str | bytes = path, change: Callable[[Any], None] = lambda o: None):
        opts = session_options(ort, threads=1)
        change(opts)
        return ort.InferenceSession(model, sess_options=opts, providers=["CPUExecutionProvider"])

    def plain(sess) -> Callable[[np.ndarray], Any]:
        return lambda f: sess.run(None, {"field_ut": f[None], "eps": eps})

    def bound(sess) -> Callable[[np.ndarray], Any]:
        return OneReadingBinding(sess, input_shape=rec.input_shape, output_hw=rec.output_shape, samples=1,
                                 latent=rec.latent).run

    spin_off = lambda o: o.add_session_config_entry("session.intra_op.allow_spinning", "0")  # noqa: E731
    return {
        "settings, session.run": plain(session()),
        "optimisation basic": plain(session(change=lambda o: setattr(o, "graph_optimization_level",
                                                                      level.ORT_ENABLE_BASIC))),
        "optimisation extended": plain(session(change=lambda o: setattr(o, "graph_optimization_level",
                                                                         level.ORT_ENABLE_EXTENDED))),
        "memory patterns off": plain(session(change=lambda o: setattr(o, "enable_mem_pattern", False))),
        "spinning off": plain(session(change=spin_off)),
        "parallel execution": plain(session(change=lambda o: setattr(o, "execution_mode",
                                                                      ort.ExecutionMode.ORT_PARALLEL))),
        "batch fixed to 1": plain(session(fixed_batch_graph(path))),
        "io_binding": bound(session()),
        "batch fixed to 1 + io_binding": bound(session(fixed_batch_graph(path))),
        "OnnxReconstructor.reconstruct": rec.reconstruct,
    }


def measure(calls: dict[str, Callable[[np.ndarray], Any]], readings: np.ndarray, rounds: int) -> dict[str, Any]:
    for call in calls.values():
        for f in readings[:10]:
            call(f)
    wall: dict[str, list[float]] = {k: [] for k in calls}
    cpu: dict[str, list[float]] = {k: [] for k in calls}
    rng, names = np.random.default_rng(0), list(calls)
    for _ in range(rounds):
        for f in readings:
            for name in rng.permutation(names):  # no variant always runs first (warm caches) or last
                call = calls[name]
                t0, c0 = time.perf_counter(), time.thread_time()
                call(f)
                c1, t1 = time.thread_time(), time.perf_counter()
                wall[name].append((t1 - t0) * 1e3)
                cpu[name].append((c1 - c0) * 1e3)
    return {name: {"p50_ms": float(np.percentile(wall[name], 50)), "p99_ms": float(np.percentile(wall[name], 99)),
                   "cpu_p50_ms": float(np.percentile(cpu[name], 50)), "calls": len(wall[name])} for name in calls}


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    base = report["variants"]["settings, session.run"]["cpu_p50_ms"]
    lines = [f"onnxruntime options, one reading, one thread, {report['model']}; {m['cpu_model']}, "
             f"{m['usable_cores']} cores, load average {m.get('load_average')}", "",
             "| variant | wall p50 ms | wall p99 ms | thread CPU p50 ms | CPU vs settings |", "|---|---|---|---|---|"]
    for name, r in report["variants"].items():
        lines.append(f"| {name} | {r['p50_ms']:.3f} | {r['p99_ms']:.3f} | {r['cpu_p50_ms']:.3f} | "
                     f"{r['cpu_p50_ms'] / base - 1:+.1%} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="experiments/model_variants/supermag_fast.onnx")
    parser.add_argument("--readings", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--out", default="docs/results/benchmarks/session_options.json")
    args = parser.parse_args()
    fields, _ = rod_readings(args.readings, 0)
    report = {"machine": machine_info(), "model": args.model,
              "variants": measure(variants(args.model), fields.astype(np.float32), args.rounds)}
    publish(report, args.out, markdown)


if __name__ == "__main__":
    main()
