"""The log line of each task's result: what a trial did, scored, as a
:class:`~tactile_manip.trials.record.TrialRecord`."""

from __future__ import annotations

from tactile_manip.behaviours.grip import GripConfig, GripResult
from tactile_manip.behaviours.place import PlaceResult
from tactile_manip.behaviours.reorient import ReorientResult
from tactile_manip.perception.pose import wrap_axial
from tactile_manip.trials.presentation import Presentation
from tactile_manip.trials.record import TrialRecord


def make_record(p: Presentation, method: str, target_rad: float, result: ReorientResult, *,
                commanded_force_n: float | None = None, task: str | None = "reorient") -> TrialRecord:
    """The log line of one trial (a correction without a measured final angle is "unmeasured").

    ``commanded_force_n``: the behaviour's grasp force, logged as ``extra["commanded_force_n"]`` beside the
    grip force a contact model estimated (``result.contact``); ``task``: the scene's task, named in the line.
    """
    est = result.estimate
    grip = result.contact
    outcome, detail = result.outcome, result.detail
    if outcome == "done" and result.error_rad is None:
        outcome, detail = "unmeasured", "the final angle was not measured"
    return TrialRecord(
        trial=p.trial, seed=p.seed, method=method, object=p.obj.display_name, true_angle_rad=p.angle_rad,
        offset_mm=p.offset_mm, target_angle_rad=float(wrap_axial(target_rad)),
        estimated_angle_rad=est.angle_rad if est is not None and est.defined else None,
        confidence=est.confidence if est is not None else 0.0, defined=bool(est is not None and est.defined),
        action=result.action, regrasps=result.regrasps, final_angle_rad=result.final_angle_rad,
        error_rad=result.error_rad, outcome=outcome, detail=detail,
        timings_s={k: round(v, 6) for k, v in result.timings_s.items()},
        extra={"force_n": round(p.force_n, 4), "grasp_width_m": result.grasp_width_m, **_sensor_extra(p),
               "correction_rad": result.correction_rad, "escalated": bool(est is not None and est.escalated),
               "estimate_timings_s": dict(est.timings_s) if est is not None else {},
               **({} if commanded_force_n is None else {"commanded_force_n": float(commanded_force_n)})},
        estimated_grip_force_n=_rounded(None if grip is None else grip.force_n),
        estimated_grip_force_sigma_n=_rounded(None if grip is None else grip.force_sigma_n), task=task)


def make_place_record(p: Presentation, method: str, result: PlaceResult, *, clearance_mm: float) -> TrialRecord:
    """The log line of one placement: ``error_rad`` is the rod's axial angle to the slot, ``lateral_error_mm``
    the distance from the slot's centre to its axis (a placement without a measured pose is "unmeasured")."""
    est = result.estimate
    outcome, detail = result.outcome, result.detail
    if outcome == "done" and (result.angle_error_rad is None or result.lateral_error_m is None):
        outcome, detail = "unmeasured", "the rod's final pose was not measured"
    return TrialRecord(
        trial=p.trial, seed=p.seed, method=method, object=p.obj.display_name, true_angle_rad=p.angle_rad,
        offset_mm=p.offset_mm, target_angle_rad=0.0,
        estimated_angle_rad=est.angle_rad if est is not None and est.defined else None,
        confidence=est.confidence if est is not None else 0.0, defined=bool(est is not None and est.defined),
        error_rad=result.angle_error_rad if outcome == "done" else None, outcome=outcome, detail=detail,
        task="place",
        lateral_error_mm=_rounded(None if result.lateral_error_m is None else result.lateral_error_m * 1e3),
        clearance_mm=float(clearance_mm), timings_s={k: round(v, 6) for k, v in result.timings_s.items()},
        extra={"force_n": round(p.force_n, 4), **_sensor_extra(p),
               "escalated": bool(est is not None and est.escalated)})


def make_grip_record(p: Presentation, method: str, result: GripResult, *, grip: GripConfig,
                     target_force_n: float) -> TrialRecord:
    """The log line of one grip: ``error_rad`` is the estimated in-hand angle minus the true one,
    ``lateral_error_mm`` the distance from the pad centre to the rod's axis, ``force_error_n`` the force the rod
    felt minus the target (a grip without those measured is "unmeasured")."""
    est = result.estimate
    outcome, detail = result.outcome, result.detail
    measured = None not in (result.angle_error_rad, result.centre_error_m, result.force_error_n)
    if outcome == "done" and not measured:
        outcome, detail = "unmeasured", "the final force or pose was not measured"
    grip_state = result.contact
    return TrialRecord(
        trial=p.trial, seed=p.seed, method=method, object=p.obj.display_name, true_angle_rad=p.angle_rad,
        offset_mm=p.offset_mm, target_angle_rad=0.0,
        estimated_angle_rad=est.angle_rad if est is not None and est.defined else None,
        confidence=est.confidence if est is not None else 0.0, defined=bool(est is not None and est.defined),
        action="regrasp" if result.recentres or result.force_steps else "act",
        regrasps=result.recentres + result.force_steps,
        error_rad=result.angle_error_rad if outcome == "done" else None, outcome=outcome, detail=detail, task="grip",
        lateral_error_mm=_rounded(None if result.centre_error_m is None else result.centre_error_m * 1e3),
        clearance_mm=float(grip.centre_tolerance_mm), force_error_n=_rounded(result.force_error_n),
        force_tolerance_n=float(grip.force_tolerance_n),
        timings_s={k: round(v, 6) for k, v in result.timings_s.items()},
        extra={"force_n": round(p.force_n, 4), **_sensor_extra(p), "commanded_force_n": float(target_force_n),
               "final_command_n": _rounded(result.commanded_force_n), "applied_force_n": _rounded(result.true_force_n),
               "force_steps": result.force_steps, "recentres": result.recentres,
               "position_mm": None if result.position_mm is None else [round(v, 4) for v in result.position_mm],
               "escalated": bool(est is not None and est.escalated)},
        estimated_grip_force_n=_rounded(None if grip_state is None or not grip_state.plausible else grip_state.force_n),
        estimated_grip_force_sigma_n=_rounded(None if grip_state is None or not grip_state.plausible
                                              else grip_state.force_sigma_n))


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(float(value), 4)


def _sensor_extra(p: Presentation) -> dict:
    params = p.sensor_params()
    if params is None:
        return {}
    from tactile_manip.sim.params import randomised_values

    return {"sensor": {k: round(v, 6) for k, v in randomised_values(params).items()}}
