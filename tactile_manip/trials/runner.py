"""Run a trial scene: every presentation once per method, in the scene's cell, logged as it completes.

The parts, each in its module: the task (:mod:`tactile_manip.behaviours.task`, looked up in
:mod:`tactile_manip.behaviours.registry`), the presentations (:mod:`~tactile_manip.trials.presentation`), the
methods' estimators (:mod:`~tactile_manip.trials.methods`), the cells (:mod:`~tactile_manip.trials.cells`: the
simulated one and the real FR3's operator cell), the log line (:mod:`~tactile_manip.trials.task_records`), the
log (:mod:`~tactile_manip.trials.log`) and the report (:mod:`~tactile_manip.trials.report`). This module runs
them: :func:`run_trials` is the one driver, and an executor runs the trials for it (:class:`LocalExecutor` in
this process; ``tactile_manip.cluster.trials.RayExecutor`` as Ray tasks).

Each (trial, method) is appended to ``trials.jsonl`` and fsynced as soon as it completes; ``resume=True``
skips the pairs already there, so a killed run loses no completed trial and can be continued.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from tactile_manip.perception.pose import wrap_axial
from tactile_manip.trials.cells import Cell, make_cell, make_task
from tactile_manip.trials.methods import build_tactile_estimators
from tactile_manip.trials.presentation import Presentation, draw_presentation
from tactile_manip.trials.record import TrialRecord
from tactile_manip.trials.scene import TrialScene
from tactile_manip.trials.task_records import error_record, make_record

if TYPE_CHECKING:
    from tactile_manip.perception.tactile_estimator import TactileEstimator


def run_scene(scene: TrialScene, write: Callable[[TrialRecord], None], *,
              estimators: Mapping[str, TactileEstimator],
              skip: set[tuple[int, str]] = frozenset(), progress: bool = True, cell: Cell | None = None,
              trial_observer=None, frames_dir: str | Path | None = None) -> int:
    """Run every (trial, method) of ``scene`` not in ``skip``; ``write`` each record.

    ``estimators``: what each method's task is handed, by method name (:func:`build_tactile_estimators`).

    ``cell`` (default: built from ``scene.robot.backend``: :class:`SimulatedCell` for the twin,
    :class:`~tactile_manip.trials.operator.OperatorCell` for a real FR3) provides ``connected()`` and ``run_one``.
    ``trial_observer`` (e.g. :class:`~tactile_manip.interop.rerun_trials.RerunTrialObserver`), when given, is told
    ``trial_started(presentation, method, cell)`` before each trial and ``trial_finished(record)`` after it
    was written; it watches, it changes nothing.
    With ``frames_dir``, each trial's per-frame streams go to ``frames_dir/<method>-<trial>.tmframes``
    (:mod:`tactile_manip.trials.frames`; the cell also needs ``sensor``, ``arm`` and ``gripper``).

    Returns the number of trials run. Outcomes other than "done" are recorded, never raised; only an
    interrupt (Ctrl-C) or a failure to build the cell stops the run.
    """
    from tqdm.auto import tqdm

    cell = cell if cell is not None else make_cell(scene)
    task = getattr(cell, "task", None) or make_task(scene)  # a cell of one's own may leave the task to the runner
    code = _code_version() if frames_dir is not None else None
    todo = [(i, m) for i in range(scene.trials) for m in estimators if (i, m) not in skip]
    faults = scene.faults
    count = 0
    holds = getattr(cell, "holds", None)
    drawn: dict[int, Presentation] = {}  # each trial drawn once for all its methods
    with cell.connected(), tqdm(total=len(todo), desc=f"trials ({scene.name})", unit="trial",
                                disable=not progress) as bar:
        for i, method in todo:
            if i not in drawn:
                drawn[i] = draw_presentation(scene, i, holds=holds)
            p = drawn[i]
            if trial_observer is not None:
                trial_observer.trial_started(p, method, cell)
            t0 = time.perf_counter()
            try:
                with _frame_stream(cell, frames_dir, p, method, scene, code) as observer:
                    kwargs = {} if observer is None else {"observer": observer}
                    result = cell.run_one(p, estimators[method], arm_fault=i in faults.arm_fault_trials,
                                          sensor_stall=i in faults.sensor_stall_trials, **kwargs)
            except Exception as exc:  # noqa: BLE001 - a broken trial is recorded, the run goes on
                result = task.failed("error", f"{type(exc).__name__}: {exc}")
            try:
                result.timings_s.setdefault("trial", time.perf_counter() - t0)
                record = make_record(p, method, task, result)
            except Exception as exc:  # noqa: BLE001 - the task's result or its log fields are broken: recorded
                record = error_record(p, method, task, f"{type(exc).__name__} while logging the trial: {exc}")
            write(record)
            if trial_observer is not None:
                trial_observer.trial_finished(record)
            count += 1
            bar.update()
    return count


def _code_version() -> str:
    from tactile_manip.version import code_version

    return code_version()


def _frame_stream(cell, frames_dir: str | Path | None, p: Presentation, method: str, scene: TrialScene,
                  code_version: str | None):
    """The trial's frame recorder (a context manager yielding the behaviour's observer), or a null one."""
    if frames_dir is None:
        return contextlib.nullcontext()
    from tactile_manip.trials.frames import TrialFrameStream

    header = {"code_version": code_version, "trial": p.trial, "method": method, "seed": p.seed,
              "object": p.obj.display_name, "scene": scene.name,
              "true_angle_rad": p.angle_rad, "offset_mm": list(p.offset_mm), "force_n": p.force_n}
    return TrialFrameStream(Path(frames_dir) / f"{method}-{p.trial:04d}.tmframes", sensor=cell.sensor, arm=cell.arm,
                            gripper=cell.gripper, header=header,
                            target_angle_rad=float(wrap_axial(math.radians(scene.target_deg))))


@dataclass
class TrialWork:
    """What an executor runs: the (trial, method) pairs of ``scene`` not in ``skip``, each record handed to the
    driver's ``write`` in trial order.

    ``cell`` and ``estimators`` were built by the driver (a bad scene fails before the run folder exists); an
    executor that runs the trials elsewhere builds its own from ``scene`` and ``scene_path``."""

    scene: TrialScene
    scene_path: Path | None
    cell: Any
    estimators: Mapping[str, TactileEstimator]
    skip: set[tuple[int, str]] = field(default_factory=set)
    frames_dir: Path | None = None
    progress: bool = True
    trial_observer: Any = None


class Executor(Protocol):
    """Runs a :class:`TrialWork` for :func:`run_trials`."""

    def run(self, work: TrialWork, write: Callable[[TrialRecord], None]) -> None:
        """Run every pair of ``work`` and ``write`` each record, in trial order, as it completes."""


class LocalExecutor:
    """Runs the trials in this process, in the driver's cell (:func:`run_scene`)."""

    def run(self, work: TrialWork, write: Callable[[TrialRecord], None]) -> None:
        run_scene(work.scene, write, estimators=work.estimators, skip=work.skip, progress=work.progress,
                  cell=work.cell, trial_observer=work.trial_observer, frames_dir=work.frames_dir)


def prepare(scene: TrialScene, scene_path: str | Path | None = None):
    """The scene's cell and each method's estimator (every model file found and checked), before any trial."""
    cell = make_cell(scene)
    estimators = build_tactile_estimators(scene, Path(scene_path) if scene_path is not None else None,
                                          layout=cell.sensor.layout.name)
    return cell, estimators


def run_trials(scene: TrialScene, out_dir: str | Path, *, scene_path: str | Path | None = None,
               resume: bool = False, progress: bool = True, tolerance_deg: float | None = None,
               trial_observer=None, frames: bool = True, executor: Executor | None = None):
    """Run ``scene`` into ``out_dir`` (trials.jsonl fsynced per trial, then the report) and return the summary.

    ``executor`` runs the trials (default: :class:`LocalExecutor`; ``tactile_manip.cluster.trials.RayExecutor``
    runs them as Ray tasks, to the same log). ``trial_observer``: see :func:`run_scene`. With ``frames`` (the
    default) each trial's per-frame streams go to ``out_dir/frames/`` (:mod:`tactile_manip.trials.frames`), for
    a task whose trials they suit (``Task.streams_frames``): what ``tactile-manip export`` turns into episodes.

    With ``resume=True`` the (trial, method) pairs already in ``out_dir/trials.jsonl`` are skipped (the scene
    must be the same: the log refuses a different one).
    """
    from tactile_manip.config import to_dict
    from tactile_manip.trials.log import TrialLog, completed_keys, read_run_info, read_trials
    from tactile_manip.trials.report import write_report

    out = Path(out_dir)
    where = Path(scene_path).resolve() if scene_path is not None else None
    # every part the scene names is built before the run folder is made, so a bad scene leaves no folder behind
    cell, estimators = prepare(scene, where)
    skip = completed_keys(out / "trials.jsonl") if resume and (out / "trials.jsonl").exists() else set()
    work = TrialWork(scene, where, cell, estimators, skip=skip, progress=progress, trial_observer=trial_observer,
                     frames_dir=out / "frames" if frames and cell.task.streams_frames else None)
    with TrialLog(out, config=to_dict(scene), resume=resume) as log:
        (executor or LocalExecutor()).run(work, log.append)
    tolerance = math.radians(scene.tolerance_deg if tolerance_deg is None else tolerance_deg)
    return write_report(out, read_trials(out / "trials.jsonl"), tolerance, title=f"{cell.task.title}: {scene.name}",
                        run_info=read_run_info(out), task=type(cell.task))
