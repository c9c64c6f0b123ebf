"""A task: what a trial does with the hardware it is handed, what it logs, and how its runs are reported.

A task is one class (after dm_control's ``Task``): a subclass of :class:`Task` in one module, named in the
table of :mod:`tactile_manip.behaviours.registry` (or by ``"module:Class"`` in a scene's ``task``). The trial
runner, the cells, the log, the report, ``tactile-manip score`` and the Ray driver only ever call these methods;
none of them knows a task by name. What a subclass states:

- ``name``, ``title``: the name each trial record carries (and the scene's table of the task's settings,
  ``[<name>]``; default: the class's name in lower case), and the heading of its reports;
- ``Config``: the dataclass of those settings (:class:`NoSettings` for none), validated as every config is;
- :meth:`run`: one trial, on a :class:`Trial` (arm, gripper, sensor, estimator, the object, the seed, the truth),
  returning a result (a :class:`TaskResult`, or any object with its ``outcome``, ``detail``, ``estimate`` and
  ``timings_s``);
- :meth:`failed` (optional): the result of a trial that raised (the runner records it and goes on);
- :meth:`record`: the fields its trials add to the log line (:class:`~tactile_manip.trials.record.TrialRecord`
  keyword arguments, ``extra`` merged into the line's ``extra``);
- :meth:`report` and :meth:`success_rule`: the report's sections of its own and the sentence that says when
  a trial succeeded. Success itself is scored from the record alone (``TrialRecord.succeeded``: outcome
  ``done``, ``|error_rad|`` within the tolerance, and the lateral error and force error within the clearance
  and force tolerance the record carries), so ``tactile-manip score`` re-scores a run without running code
  of the task.

Tasks live in ``behaviours/`` and import nothing of ``trials/``: records and presentations reach them as
objects with the attributes named here.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from tactile_manip.behaviours.skills import BehaviourConfig
from tactile_manip.robot.base import Arm, Gripper
from tactile_manip.sensors.base import TactileSensor


@dataclass(frozen=True)
class NoSettings:
    """The settings of a task that has none (its scene has no ``[<task name>]`` table)."""


@dataclass
class Trial:
    """What a task is handed for one trial; it acts on these, it never builds or keeps them.

    Attributes:
        arm, gripper, sensor: the cell's hardware (connected; the object is between the open fingers).
        estimator: the method's estimator (``read(sensor, frames=, timeout_s=)``).
        object_width_m: the presented object's nominal width across the fingers, m.
        seed: the presentation's seed: draw anything the task needs per trial from
            ``numpy.random.default_rng([seed, k])`` (k > 1; 1 is the slot of the placement), so every method
            meets the same draw.
        presentation: the trial's presentation (``obj``, ``angle_rad``, ``offset_mm``, ``force_n``), read only.
        truth: the cell's ground truth, for scoring only (the twin's in simulation: ``object_pose_base()``,
            ``object_axis_base()``, ``grip_force_n()``; an operator's on a real robot), or None.
        observer: told the behaviour's phases (a trial's frame recorder), or None.
    """

    arm: Arm
    gripper: Gripper
    sensor: TactileSensor
    estimator: Any
    object_width_m: float
    seed: int
    presentation: Any = None
    truth: Any = None
    observer: Any = None


@dataclass
class TaskResult:
    """What one trial of a task did: a result a task may return as it is, or subclass with its own fields.

    Attributes:
        outcome: one of the trial log's outcomes ("done", "abstained", "grasp_failed", "sensor_stale",
            "ik_failed", "arm_fault", "safety_refused", "unmeasured", "error").
        detail: what happened, for any outcome but "done".
        estimate: the angle estimate the log line shows (an ``AngleEstimate``, or what the estimator read: its
            ``angle`` is logged), or None.
        timings_s: named durations of the trial's phases, s.
    """

    outcome: str
    detail: str = ""
    estimate: Any = None
    timings_s: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class ReportSection:
    """A section of a run's report: ``data`` goes into ``summary.json`` under ``key``; ``heading``, ``columns``
    and ``rows`` into ``summary.md`` as a table."""

    key: str
    data: Any
    heading: str
    columns: Sequence[str]
    rows: Sequence[Sequence[str]] = field(default_factory=list)


class Task(abc.ABC):
    """One kind of trial (module docstring). Built once per run from the scene: ``Task(scene)``."""

    name: ClassVar[str]
    title: ClassVar[str] = "Trials"
    Config: ClassVar[type] = NoSettings
    streams_frames: ClassVar[bool] = False  # whether the trial's frame recorder suits it (a turn to a target angle)
    simulated_only: ClassVar[str] = ""      # why the task runs only in the simulated cell ("" where it does not)

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if not isinstance(getattr(cls, "name", None), str):  # a task that names itself not: its class's name
            cls.name = cls.__name__.lower()
        if cls.title == Task.title:
            cls.title = f"{cls.name.capitalize()} trials"

    def __init__(self, scene: Any) -> None:
        self.scene = scene
        self.config = scene.settings
        self.behaviour: BehaviourConfig = scene.behaviour

    @classmethod
    def check_scene(cls, scene: Any) -> None:
        """Refuse a scene this task cannot run (ValueError saying why); the scene calls it when it is built."""
        if cls.simulated_only and scene.robot.backend != "twin":
            raise ValueError(f"task = {scene.task!r} runs in the simulated cell only (robot.backend = \"twin\"): "
                             f"{cls.simulated_only}")

    @abc.abstractmethod
    def run(self, trial: Trial) -> Any:
        """Run one trial; the result (``outcome``, ``detail``, ``estimate``, ``timings_s``). A fault of the trial
        is an outcome, never an escape (catch :class:`~tactile_manip.behaviours.skills.Abort`); the cell opens
        the gripper and resets after it."""

    def failed(self, outcome: str, detail: str) -> Any:
        """The result of a trial that raised (``outcome`` "error", ``detail`` the exception); by default a
        :class:`TaskResult`."""
        return TaskResult(outcome=outcome, detail=detail)

    @abc.abstractmethod
    def record(self, result: Any) -> dict[str, Any]:
        """The fields this task adds to the trial's log line: keyword arguments of
        :class:`~tactile_manip.trials.record.TrialRecord` (``error_rad``, ``final_angle_rad``,
        ``target_angle_rad``, ``lateral_error_mm``, ...), ``extra`` (merged into the line's ``extra``), and
        ``outcome`` / ``detail`` where they differ from the result's (a done trial nobody measured:
        "unmeasured"). The runner adds what every trial has: the presentation, the method, the estimate, the
        outcome, the timings."""

    @classmethod
    def report(cls, records: Sequence[Any]) -> list[ReportSection]:
        """The report's sections of this task, from a run's records (none by default)."""
        return []

    @classmethod
    def success_rule(cls, records: Sequence[Any]) -> str:
        """The report's sentence of what a success is, up to the angle tolerance that follows it."""
        return "Success: outcome `done` and |final - target| <="


def rounded(value: float | None, digits: int = 4) -> float | None:
    """``value`` rounded for a log line (None stays None)."""
    return None if value is None else round(float(value), digits)


def lateral_errors(records: Sequence[Any]) -> dict[str, dict[str, Any]]:
    """Per method, the lateral errors of a run's records (mm): how many trials measured one, median, p95, and
    how many are within the clearance (None where a method measured none)."""
    out = {}
    for method in dict.fromkeys(r.method for r in records):
        mine = [r for r in records if r.method == method and r.lateral_error_mm is not None]
        lateral = [r.lateral_error_mm for r in mine]
        out[method] = {"n": len(mine), "median_mm": percentile(lateral, 50), "p95_mm": percentile(lateral, 95),
                       "within_clearance": sum(r.within_clearance for r in mine)}
    return out


def lateral_section(records: Sequence[Any], heading: str, done: str) -> ReportSection:
    """The report's section of the lateral errors per method (``done``: the column of trials that measured one)."""
    errors = lateral_errors(records)
    rows = [[m, str(e["n"]), fmt2(e["median_mm"]), fmt2(e["p95_mm"]), f"{e['within_clearance']}/{e['n']}"]
            for m, e in errors.items()]
    return ReportSection("lateral_error", errors, heading,
                         ["method", done, "median (mm)", "p95 (mm)", "within the clearance"], rows)


def percentile(values, q: float) -> float | None:
    """The ``q``-th percentile of ``values`` (None when there are none)."""
    return float(np.percentile(values, q)) if len(values) else None


def fmt2(x: float | None) -> str:
    """``x`` with two decimals for a report's table ("-" for None)."""
    return "-" if x is None else f"{x:.2f}"
