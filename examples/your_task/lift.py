"""A task of your own, in one module: grasp the rod, read its in-hand angle, lift it, read it again, and score the
angle read after the lift against the true one (docs/your_task.md builds it step by step)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_manip.behaviours.skills import Abort, approach, grasp, read_pad
from tactile_manip.behaviours.task import ReportSection, Task, TaskResult, fmt2, percentile
from tactile_manip.checks import check_finite_scalar
from tactile_manip.perception.pose import wrap_axial


@dataclass(frozen=True)
class LiftConfig:
    """The scene's ``[lift]`` table.

    Attributes:
        height_mm: how far the hand lifts the grasped rod, mm.
    """

    height_mm: float = 20.0

    def __post_init__(self) -> None:
        check_finite_scalar("lift.height_mm", self.height_mm, low=0.0, low_open=True, high=100.0)


@dataclass
class LiftResult(TaskResult):
    """What one lift did: ``estimate`` is the angle read after the lift (what the trial is scored on), ``before``
    the one read before it; the outcome, detail and timings as every result has them."""

    before: Any = None
    true_angle_rad: float | None = None


class Lift(Task):
    """Grasp, read, lift by ``height_mm``, read again; ``error_rad``: the angle read after the lift minus the
    rod's true in-hand angle."""

    name = "lift"
    title = "Lift trials"
    Config = LiftConfig

    def run(self, trial) -> LiftResult:
        result = LiftResult(outcome="error", true_angle_rad=trial.presentation.angle_rad)
        try:
            grasp(trial.arm, trial.gripper, trial.object_width_m, self.behaviour)
            result.before = read_pad(trial.sensor, trial.estimator, self.behaviour).angle
            approach(trial.arm, np.array([0.0, 0.0, self.config.height_mm * 1e-3]), self.behaviour, "lift")
            result.estimate = read_pad(trial.sensor, trial.estimator, self.behaviour).angle
            result.outcome = "done"
        except Abort as stop:
            result.outcome, result.detail = stop.outcome, stop.detail
        return result

    def failed(self, outcome: str, detail: str) -> LiftResult:
        return LiftResult(outcome=outcome, detail=detail)

    def record(self, result: LiftResult) -> dict:
        est, before = result.estimate, result.before
        done = result.outcome == "done" and est is not None and est.defined
        outcome = result.outcome if done or result.outcome != "done" else "abstained"
        error = float(wrap_axial(est.angle_rad - result.true_angle_rad)) if done else None
        change = (float(wrap_axial(est.angle_rad - before.angle_rad))
                  if done and before is not None and before.defined else None)
        return {"outcome": outcome, "detail": result.detail or ("" if done else "no angle after the lift"),
                "error_rad": error, "extra": {"lift_mm": self.config.height_mm, "change_rad": change}}

    @classmethod
    def report(cls, records) -> list[ReportSection]:
        rows, data = [], {}
        for method in dict.fromkeys(r.method for r in records):
            change = [abs(r.extra["change_rad"]) for r in records
                      if r.method == method and r.extra.get("change_rad") is not None]
            data[method] = {"n": len(change), "median_deg": percentile(np.degrees(change), 50)}
            rows.append([method, str(len(change)), fmt2(data[method]["median_deg"])])
        return [ReportSection("lift_change", data, "How far the angle read moved over the lift", ["method", "lifted",
                              "median abs change (deg)"], rows)]

    @classmethod
    def success_rule(cls, records) -> str:
        return "Success: outcome `done` and |angle read after the lift - true angle| <="

