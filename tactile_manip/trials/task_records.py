"""The log line of a trial: what every trial has (the presentation, the method, the estimate, the outcome, the
timings), joined with the fields its task adds (:meth:`~tactile_manip.behaviours.task.Task.record`), as a
:class:`~tactile_manip.trials.record.TrialRecord`."""

from __future__ import annotations

from typing import Any

from tactile_manip.behaviours.task import Task
from tactile_manip.trials.presentation import Presentation
from tactile_manip.trials.record import TrialRecord


def make_record(p: Presentation, method: str, task: Task, result: Any) -> TrialRecord:
    """The log line of one trial of ``task`` (``result``: what its ``run`` or ``failed`` returned)."""
    fields = dict(task.record(result) or {})
    extra = fields.pop("extra", None) or {}
    est = getattr(result.estimate, "angle", result.estimate)  # what an estimator read carries its angle
    return TrialRecord(
        trial=p.trial, seed=p.seed, method=method, object=p.obj.display_name, true_angle_rad=p.angle_rad,
        offset_mm=p.offset_mm, target_angle_rad=fields.pop("target_angle_rad", 0.0),
        estimated_angle_rad=est.angle_rad if est is not None and est.defined else None,
        confidence=est.confidence if est is not None else 0.0, defined=bool(est is not None and est.defined),
        outcome=fields.pop("outcome", result.outcome), detail=fields.pop("detail", result.detail),
        timings_s={k: round(v, 6) for k, v in result.timings_s.items()},
        extra={"force_n": round(p.force_n, 4), **_sensor_extra(p), **extra,
               "escalated": bool(est is not None and getattr(est, "escalated", False))},
        task=task.name, **fields)


def error_record(p: Presentation, method: str, task: Task, detail: str) -> TrialRecord:
    """The log line of a trial whose task could not make one (its ``record`` raised): outcome "error"."""
    return TrialRecord(trial=p.trial, seed=p.seed, method=method, object=p.obj.display_name,
                       true_angle_rad=p.angle_rad, offset_mm=p.offset_mm, target_angle_rad=0.0, outcome="error",
                       detail=detail, extra={"force_n": round(p.force_n, 4), **_sensor_extra(p)}, task=task.name)


def _sensor_extra(p: Presentation) -> dict:
    params = p.sensor_params()
    if params is None:
        return {}
    from tactile_manip.sim.params import randomised_values

    return {"sensor": {k: round(v, 6) for k, v in randomised_values(params).items()}}
