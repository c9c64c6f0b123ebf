"""``trials --ray``: a trial scene's presentations as Ray tasks, logged as the local run logs them.

A task runs a block of trial indices, every method of each (so a drawn sensor is shared by the methods of a
trial, as locally), in a work cell of its own that the worker builds once and keeps. Every presentation draws
from its own seed, so each (trial, method) gives the outcome of the local run; the driver appends the records to
``trials.jsonl`` in trial order as blocks finish, so a killed run keeps every block logged before the kill and
``--resume`` continues it. Per-frame streams are written by the workers into the run folder, which therefore must
be on a file system the workers share (a private local instance always is; else pass ``--no-frames``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from tactile_manip.cluster.connect import ray_session
from tactile_manip.trials.record import TrialRecord
from tactile_manip.trials.scene import TrialScene

MAX_RETRIES = 3          # Ray re-runs a block this often when its worker process dies
DEFAULT_BLOCK_TRIALS = 4  # presentations per task (every method of each)

_WORKER: dict[str, Any] = {}


def run_trial_block(scene: TrialScene, scene_path: str | None, trials: list[int], methods: list[str],
                    frames_dir: str | None) -> list[TrialRecord]:
    """Run ``methods`` on each presentation in ``trials`` in this process's cell; the records in run order."""
    from tactile_manip.trials.cells import make_cell
    from tactile_manip.trials.methods import build_tactile_estimators
    from tactile_manip.trials.runner import run_scene

    key = (repr(scene), scene_path)
    if _WORKER.get("key") != key:  # the cell and the models are built once per worker and scene
        _WORKER.clear()
        where = Path(scene_path) if scene_path else None
        cell = make_cell(scene)
        _WORKER.update(key=key, cell=cell,
                       estimators=build_tactile_estimators(scene, where, layout=cell.sensor.layout.name))
    wanted = set(trials)
    skip = {(i, m) for i in range(scene.trials) for m in _WORKER["estimators"] if i not in wanted or m not in methods}
    records: list[TrialRecord] = []
    run_scene(scene, records.append, estimators=_WORKER["estimators"], skip=skip, progress=False,
              cell=_WORKER["cell"], frames_dir=frames_dir)
    return records


def run_trials_on_ray(scene: TrialScene, out_dir: str | Path, *, scene_path: str | Path | None = None,
                      resume: bool = False, progress: bool = True, frames: bool = True,
                      address: str | None = None, num_cpus: int | None = None,
                      block_trials: int = DEFAULT_BLOCK_TRIALS):
    """:func:`tactile_manip.trials.runner.run_trials` with the trials as Ray tasks; returns the summary."""
    from tactile_manip.config import to_dict
    from tactile_manip.trials.log import TrialLog, completed_keys, read_run_info, read_trials
    from tactile_manip.trials.report import write_report
    from tactile_manip.trials.cells import make_cell
    from tactile_manip.trials.methods import build_tactile_estimators
    from tactile_manip.trials.scene import TASK_TITLES

    if block_trials < 1:
        raise ValueError(f"--block-trials must be >= 1, got {block_trials}")
    out = Path(out_dir)
    scene_file = str(Path(scene_path).resolve()) if scene_path is not None else None
    cell = make_cell(scene)  # a bad scene fails here, before the run folder is made
    estimators = build_tactile_estimators(scene, Path(scene_file) if scene_file else None,
                                          layout=cell.sensor.layout.name)
    methods = list(estimators)
    skip = completed_keys(out / "trials.jsonl") if resume and (out / "trials.jsonl").exists() else set()
    todo = [i for i in range(scene.trials) if any((i, m) not in skip for m in methods)]
    blocks = [todo[k:k + block_trials] for k in range(0, len(todo), block_trials)]
    with ray_session(address, num_cpus=num_cpus) as ray, TrialLog(out, config=to_dict(scene), resume=resume) as log:
        _run_blocks(ray, scene, scene_file, blocks, methods, log, skip,
                    frames_dir=str(out / "frames") if frames and scene.task == "reorient" else None, progress=progress)
    tolerance = math.radians(scene.tolerance_deg)
    return write_report(out, read_trials(out / "trials.jsonl"), tolerance,
                        title=f"{TASK_TITLES[scene.task]}: {scene.name}", run_info=read_run_info(out), task=scene.task)


def _run_blocks(ray: Any, scene: TrialScene, scene_file: str | None, blocks: list[list[int]], methods: list[str],
                log, skip: set[tuple[int, str]], *, frames_dir: str | None, progress: bool) -> None:
    from tqdm.auto import tqdm

    task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(run_trial_block)
    scene_ref = ray.put(scene)
    pending = {task.remote(scene_ref, scene_file, b, methods, frames_dir): k for k, b in enumerate(blocks)}
    finished: dict[int, list[TrialRecord]] = {}
    next_block = 0
    total = sum(1 for b in blocks for i in b for m in methods if (i, m) not in skip)
    try:
        with tqdm(total=total, desc=f"trials ({scene.name}, Ray)", unit="trial", disable=not progress) as bar:
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                finished[pending.pop(ready[0])] = ray.get(ready[0])
                while next_block in finished:  # the log stays in trial order: append blocks as they connect
                    for record in finished.pop(next_block):
                        if (record.trial, record.method) not in skip:
                            log.append(record)
                        bar.update()
                    next_block += 1
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
