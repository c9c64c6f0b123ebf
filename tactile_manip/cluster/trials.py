"""``trials --ray``: the executor that runs a trial scene's presentations as Ray tasks, for the one trials driver
(:func:`tactile_manip.trials.runner.run_trials`), which logs and reports them as it does a local run.

A Ray task runs a block of trial indices, every method of each (so a drawn sensor is shared by the methods of a
trial, as locally), in a work cell of its own that the worker builds once and keeps. Every presentation draws
from its own seed, so each (trial, method) gives the outcome of the local run; the driver appends the records to
``trials.jsonl`` in trial order as blocks finish, so a killed run keeps every block logged before the kill and
``--resume`` continues it. Per-frame streams are written by the workers into the run folder, which therefore must
be on a file system the workers share (a private local instance always is; else pass ``--no-frames``).

A task of your own (``task = "module:Class"``) must import on the workers too: for a private local instance the
folder its module was imported from is put on the workers' path; on a cluster, install it on every node.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from tactile_manip.cluster.connect import check_workers_import, ray_session
from tactile_manip.trials.record import TrialRecord
from tactile_manip.trials.runner import TrialWork
from tactile_manip.trials.scene import TrialScene

MAX_RETRIES = 3          # Ray re-runs a block this often when its worker process dies
DEFAULT_BLOCK_TRIALS = 4  # presentations per task (every method of each)

_WORKER: dict[str, Any] = {}


def run_trial_block(scene: TrialScene, scene_path: str | None, trials: list[int], methods: list[str],
                    frames_dir: str | None) -> list[TrialRecord]:
    """Run ``methods`` on each presentation in ``trials`` in this process's cell; the records in run order."""
    from tactile_manip.trials.runner import prepare, run_scene

    key = (repr(scene), scene_path)
    if _WORKER.get("key") != key:  # the cell and the models are built once per worker and scene
        _WORKER.clear()
        cell, estimators = prepare(scene, scene_path)
        _WORKER.update(key=key, cell=cell, estimators=estimators)
    wanted = set(trials)
    skip = {(i, m) for i in range(scene.trials) for m in _WORKER["estimators"] if i not in wanted or m not in methods}
    records: list[TrialRecord] = []
    run_scene(scene, records.append, estimators=_WORKER["estimators"], skip=skip, progress=False,
              cell=_WORKER["cell"], frames_dir=frames_dir)
    return records


class RayExecutor:
    """Runs a :class:`~tactile_manip.trials.runner.TrialWork` as Ray tasks of ``block_trials`` presentations.

    Args:
        address: ``None`` / "local" (a private instance on this machine), "auto" or ``HOST:PORT``
            (:func:`~tactile_manip.cluster.connect.ray_session`).
        num_cpus: CPUs of a private local instance (None: all).
        block_trials: presentations per Ray task (every method of each).
    """

    def __init__(self, address: str | None = None, *, num_cpus: int | None = None,
                 block_trials: int = DEFAULT_BLOCK_TRIALS) -> None:
        if block_trials < 1:
            raise ValueError(f"--block-trials must be >= 1, got {block_trials}")
        self.address, self.num_cpus, self.block_trials = address, num_cpus, block_trials

    def run(self, work: TrialWork, write: Callable[[TrialRecord], None]) -> None:
        from tactile_manip.behaviours.registry import task_root

        if work.trial_observer is not None:
            raise ValueError("a trial observer watches trials in this process; it cannot watch Ray workers")
        methods = list(work.estimators)
        todo = [i for i in range(work.scene.trials) if any((i, m) not in work.skip for m in methods)]
        blocks = [todo[k:k + self.block_trials] for k in range(0, len(todo), self.block_trials)]
        task_cls = type(work.cell.task)
        root = task_root(task_cls)
        with ray_session(self.address, num_cpus=self.num_cpus, python_path=[root] if root else []) as ray:
            if root is not None:
                check_workers_import(ray, task_cls.__module__)
            _run_blocks(ray, work, blocks, methods, write)


def _run_blocks(ray: Any, work: TrialWork, blocks: list[list[int]], methods: list[str],
                write: Callable[[TrialRecord], None]) -> None:
    from tqdm.auto import tqdm

    task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(run_trial_block)
    scene_ref = ray.put(work.scene)
    scene_file = str(work.scene_path) if work.scene_path is not None else None
    frames_dir = str(work.frames_dir) if work.frames_dir is not None else None
    pending = {task.remote(scene_ref, scene_file, b, methods, frames_dir): k for k, b in enumerate(blocks)}
    finished: dict[int, list[TrialRecord]] = {}
    next_block = 0
    total = sum(1 for b in blocks for i in b for m in methods if (i, m) not in work.skip)
    try:
        with tqdm(total=total, desc=f"trials ({work.scene.name}, Ray)", unit="trial",
                  disable=not work.progress) as bar:
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                finished[pending.pop(ready[0])] = ray.get(ready[0])
                while next_block in finished:  # the log stays in trial order: append blocks as they connect
                    for record in finished.pop(next_block):
                        if (record.trial, record.method) not in work.skip:
                            write(record)
                        bar.update()
                    next_block += 1
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
