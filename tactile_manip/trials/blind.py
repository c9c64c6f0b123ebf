"""The baseline without tactile input: a method that reads the sensor as the others do and ignores what it says.

Every task is scored against it (``reconstructor = "blind"`` on a scene's method): it answers the prior of the
presentation, the rod along the pad's x axis through the pad centre, with full confidence, so the behaviour acts
on it exactly as on a tactile estimate. What the tactile methods gain over it is what touch is worth in that
task: a reorientation succeeds blind only when the rod happened to be presented within the tolerance of the
target, a placement only when the slot's angle and the contact offset happened to allow it.
"""

from __future__ import annotations

import time

from tactile_manip.sensors.base import TactileSensor
from tactile_manip.types import AngleEstimate

BLIND = "blind"


class BlindEstimator:
    """Duck-types the estimator the behaviours read (:meth:`read`): waits for ``frames`` new frames, then answers
    angle 0 (the pad's x axis) through the pad centre, confidence 1. No reconstructor, no calibration."""

    name = BLIND
    calibration = None
    angle_head = None
    angle_source = "none"

    def read(self, sensor: TactileSensor, *, frames: int = 1, timeout_s: float = 0.1) -> AngleEstimate:
        if not isinstance(frames, int) or frames < 1:
            raise ValueError(f"frames must be a positive integer, got {frames!r}")
        start_s, t0 = time.monotonic(), time.perf_counter()
        seen = 0
        while seen < frames:  # the same sensor traffic as a tactile method: a stalled sensor still ends the trial
            if sensor.wait_new(timeout_s).t_host_s >= start_s:
                seen += 1
        return AngleEstimate(angle_rad=0.0, confidence=1.0, defined=True, centroid_mm=(0.0, 0.0), source="prior",
                             timings_s={"total": time.perf_counter() - t0})
