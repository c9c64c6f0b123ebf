"""The baselines every tactile method is scored against, as estimators of the same interface.

- The interpolation baselines (the paper's): ``TactileEstimator.load("bilinear")`` or ``"bicubic"``, the 4x4
  z-axis map upsampled behind the same pose pipeline
  (:class:`~tactile_manip.perception.reconstruct.InterpolationReconstructor`).
- The blind baseline, without tactile input (:func:`blind_estimator`): it reads the sensor as the others do and
  ignores what it says. It answers the prior of a presentation, the rod along the pad's x axis through the pad
  centre, with full confidence, so a behaviour acts on it exactly as on a tactile estimate. What the tactile
  methods gain over it is what touch is worth in a task: a reorientation succeeds blind only when the rod
  happened to be presented within the tolerance of the target, a placement only when the slot's angle and the
  contact offset happened to allow it.

Both are :class:`~tactile_manip.perception.tactile_estimator.TactileEstimator` objects, so they implement
:class:`~tactile_manip.perception.tactile_estimator.Estimator`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from tactile_manip.perception.tactile_estimator import TactileEstimator
from tactile_manip.types import AngleEstimate, TactileReading

BLIND = "blind"  # the name a scene's method gives the blind baseline (``reconstructor = "blind"``)


class _AnyBoardPose:
    """What the pose parts without a model share: they read any board's readings, with no reconstructor,
    calibration or angle head."""

    name = ""
    calibration = None
    angle_head = None
    angle_source = ""
    input_shape = None  # any reading
    board_layout = ""  # any board
    min_contact_area_mm2 = 0.0

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def check_layout(self, layout: str) -> None:
        """Any board's sensor is read (a contact model beside it checks its own board)."""


class BlindPoseEstimator(_AnyBoardPose):
    """The pose part of the blind baseline: angle 0 (the pad's x axis) through the pad centre, confidence 1, for
    any reading of any board. No reconstructor, no calibration, no angle head."""

    name = BLIND
    angle_source = "prior"

    def estimate(self, reading: TactileReading | np.ndarray) -> AngleEstimate:
        """The prior, whatever ``reading`` holds."""
        return _prior(time.perf_counter())

    def estimate_many(self, readings: Sequence[TactileReading | np.ndarray]) -> list[AngleEstimate]:
        """The prior for each reading."""
        t0 = time.perf_counter()
        return [_prior(t0) for _ in readings]

    def estimate_frames(self, readings: Sequence[TactileReading | np.ndarray]) -> AngleEstimate:
        """The prior (ValueError for no reading, as every pose part)."""
        if len(readings) == 0:
            raise ValueError("estimate_frames needs at least one reading")
        return _prior(time.perf_counter())


NO_POSE_MODEL = "no pose model"  # the reason of every angle of an estimator without a pose model


class NoPoseEstimator(_AnyBoardPose):
    """The pose part of an estimator whose board has a contact model and no pose model (an AnySkin or eFlesh
    board, say): every angle is undefined (``reason`` :data:`NO_POSE_MODEL`, confidence 0), so nothing acts on
    one, and the estimates' ``position_mm`` is the contact model's. Reads any board's readings."""

    name = "none"
    angle_source = "none"

    def estimate(self, reading: TactileReading | np.ndarray) -> AngleEstimate:
        """No angle."""
        return AngleEstimate(0.0, 0.0, False, reason=NO_POSE_MODEL, source="none")

    def estimate_many(self, readings: Sequence[TactileReading | np.ndarray]) -> list[AngleEstimate]:
        """No angle, for each reading."""
        return [self.estimate(r) for r in readings]

    def estimate_frames(self, readings: Sequence[TactileReading | np.ndarray]) -> AngleEstimate:
        """No angle (ValueError for no reading, as every pose part)."""
        if len(readings) == 0:
            raise ValueError("estimate_frames needs at least one reading")
        return self.estimate(readings[-1])


def _prior(t0: float) -> AngleEstimate:
    return AngleEstimate(angle_rad=0.0, confidence=1.0, defined=True, centroid_mm=(0.0, 0.0), source="prior",
                         timings_s={"total": time.perf_counter() - t0})


def blind_estimator() -> TactileEstimator:
    """The blind baseline as an estimator: it waits for the sensor's frames as a tactile method does (a stalled
    sensor still ends the trial), then answers the prior; no contact model."""
    return TactileEstimator(BlindPoseEstimator())
