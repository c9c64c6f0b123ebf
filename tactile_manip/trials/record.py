"""One trial as it is logged: a flat, JSON-serialisable record (one line per trial).

Outcomes (``outcome``) say what happened; ``success`` is derived from ``outcome`` and ``error_rad`` at a
tolerance, so a run can be re-scored at another tolerance without re-running it (``tactile-manip score``).

- ``"done"``: the correction was executed and the true final angle measured (``error_rad`` set).
- ``"abstained"``: the estimate was undefined or below the confidence threshold and the policy abstained.
- ``"grasp_failed"``: the gripper did not close on the object within its width tolerance.
- ``"sensor_stale"``: the tactile sensor stopped delivering fresh frames mid-trial; the trial was aborted.
- ``"ik_failed"``: no joint path reached the corrected pose (the arm did not move).
- ``"arm_fault"``: the arm stopped on a fault mid-motion; it was recovered before the next trial.
- ``"safety_refused"``: the safety layer refused the corrected pose (outside joint, workspace or speed limits).
- ``"unmeasured"``: the correction was executed but nobody measured the final angle (a real-robot trial whose
  operator left the measurement blank).
- ``"error"``: anything else (``detail`` holds the message).

Every outcome other than ``"done"`` counts as a failure of the trial.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

OUTCOMES = ("done", "abstained", "grasp_failed", "sensor_stale", "ik_failed", "arm_fault", "safety_refused",
            "unmeasured", "error")
RECORD_VERSION = 1
OPTIONAL_FIELDS = ("estimated_grip_force_n", "estimated_grip_force_sigma_n", "task", "lateral_error_mm",
                   "clearance_mm", "force_error_n", "force_tolerance_n")  # left out of a line when None


@dataclass
class TrialRecord:
    """Everything logged about one trial (angles in rad, axial angles wrapped to (-pi/2, pi/2]).

    Attributes:
        trial: index of the presentation within the run (the same index for every method).
        seed: seed of the presentation (object, angle, offset); identical across methods for a paired comparison.
        method: reconstructor name, e.g. "supermag" or "bilinear".
        object: object label.
        true_angle_rad: the object's true in-hand angle in the pad frame at grasp.
        offset_mm: contact offset (x, y) in the pad frame at grasp, mm.
        target_angle_rad: commanded final angle of the object in the pad frame at grasp.
        estimated_angle_rad: the estimator's in-hand angle (None when undefined or not reached).
        confidence: the estimate's confidence in [0, 1] (0 when undefined or not reached).
        defined: whether the estimate was defined.
        action: what the low-confidence policy decided: "act", "regrasp" (then acted) or "abstain".
        regrasps: how many re-grasps were made.
        final_angle_rad: the object's true final angle after the correction (None when not executed).
        error_rad: signed axial error final - target (None when not executed).
        outcome: one of OUTCOMES.
        detail: human-readable reason for a non-"done" outcome.
        estimated_grip_force_n: the normal force on the pad that the scene's contact model read at the estimate
            step, N (None without a contact model, or when the trial ended before it; the line then leaves it
            out). The behaviour's commanded force is ``extra["commanded_force_n"]``.
        estimated_grip_force_sigma_n: its sigma (one standard deviation of the model's estimate), N.
        task: the name of the task the trial ran (``Task.name``; None in lines written before trials named it:
            the default task of :mod:`tactile_manip.behaviours.registry`).
        lateral_error_mm: distance from the task's target point to the rod's true axis, mm: the slot's centre
            when placing, the pad centre when gripping (None for a task without one).
        clearance_mm: the lateral error a trial may have and still succeed: the slot's clearance when placing,
            the centring tolerance when gripping.
        force_error_n: gripping: the force the object felt at the end minus the target force, N (None otherwise).
        force_tolerance_n: gripping: a grip succeeds only with |force_error_n| within it.
        timings_s: named durations of the trial's phases, s.
        extra: backend- or task-specific values (JSON-serialisable).
    """

    trial: int
    seed: int
    method: str
    object: str
    true_angle_rad: float
    offset_mm: tuple[float, float]
    target_angle_rad: float
    estimated_angle_rad: float | None = None
    confidence: float = 0.0
    defined: bool = False
    action: str = "act"
    regrasps: int = 0
    final_angle_rad: float | None = None
    error_rad: float | None = None
    outcome: str = "error"
    detail: str = ""
    estimated_grip_force_n: float | None = None
    estimated_grip_force_sigma_n: float | None = None
    task: str | None = None
    lateral_error_mm: float | None = None
    clearance_mm: float | None = None
    force_error_n: float | None = None
    force_tolerance_n: float | None = None
    timings_s: dict[str, float] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)
    version: int = RECORD_VERSION

    def __post_init__(self) -> None:
        if self.outcome not in OUTCOMES:
            raise ValueError(f"outcome must be one of {OUTCOMES}, got {self.outcome!r}")
        if self.outcome == "done" and (self.error_rad is None or not math.isfinite(self.error_rad)):
            raise ValueError("a 'done' trial needs a finite error_rad")
        if (self.estimated_grip_force_n is None) != (self.estimated_grip_force_sigma_n is None):
            raise ValueError("estimated_grip_force_n and estimated_grip_force_sigma_n come together (both or neither)")

    def succeeded(self, tolerance_rad: float) -> bool:
        """Whether the trial is a success at ``tolerance_rad`` (done, |error| <= tolerance, the lateral error
        within the clearance and the force within its tolerance where the task has them)."""
        return (self.outcome == "done" and abs(float(self.error_rad)) <= tolerance_rad and self.within_clearance
                and self.within_force)

    @property
    def within_clearance(self) -> bool:
        """The lateral error within the clearance (True for a task without one)."""
        if self.clearance_mm is None:
            return True
        return self.lateral_error_mm is not None and self.lateral_error_mm <= self.clearance_mm

    @property
    def within_force(self) -> bool:
        """A grip's force error within its tolerance (True for a task without one)."""
        if self.force_tolerance_n is None:
            return True
        return self.force_error_n is not None and abs(self.force_error_n) <= self.force_tolerance_n

    def to_dict(self) -> dict[str, Any]:
        """Plain dict for JSON (tuples become lists; the grip force is left out when there is none, so such a
        line reads as it did before trials logged it)."""
        d = dataclasses.asdict(self)
        d["offset_mm"] = list(self.offset_mm)
        for key in OPTIONAL_FIELDS:
            if d[key] is None:
                del d[key]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrialRecord:
        """Inverse of :meth:`to_dict`; unknown keys are refused with a ValueError naming them."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ValueError(f"unknown trial record fields {unknown}")
        kwargs = dict(d)
        if "offset_mm" in kwargs:
            kwargs["offset_mm"] = tuple(float(v) for v in kwargs["offset_mm"])
        return cls(**kwargs)
