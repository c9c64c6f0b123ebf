"""onnxruntime settings for reconstructing in a control loop.

:func:`session_options` holds the settings :class:`~tactile_manip.perception.reconstruct.OnnxReconstructor`
opens a model with. ``python -m benchmarks.bench_session_options`` measures each setting against the others,
interleaved (docs/results/perception_measurements.md has the figures). On the compact model, one thread, a busy
2-core VM: every graph optimisation ("all", onnxruntime's default) beat "basic" and "extended" by 9-15 % of CPU
time; turning memory patterns or spinning off, parallel execution, a graph whose batch dimension is fixed to 1 and
io_binding with buffers bound once each moved it by less than the noise (-0.1 to +5 %), so the reconstructor
keeps the plain ``session.run``. What did pay, measured later with 4000 interleaved runs: static batch and
sample dimensions together with no mean/spread tail, the one-reading graph of :mod:`.one_reading` (-11 %).

A contact model is another matter: its whole graph runs in about 0.055 ms, so the 0.01 ms that ``session.run``
spends around it (a dict in, new output arrays out) is a sixth of what ``session.run`` takes, and
:class:`~tactile_manip.perception.contact.ContactEstimator` binds its input and outputs once
(``python -m benchmarks.bench_contact`` measures the graph both ways, interleaved).
"""

from __future__ import annotations

from typing import Any


def session_options(ort: Any, *, threads: int) -> Any:
    """``onnxruntime.SessionOptions`` for ``threads`` intra-op threads (0: onnxruntime decides).

    Sequential execution with one inter-op thread (the decoder is one chain of nodes: nothing could run in
    parallel), every graph optimisation, memory patterns on (the shapes repeat from call to call).
    """
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = max(0, int(threads))
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    opts.enable_mem_pattern = True
    return opts
