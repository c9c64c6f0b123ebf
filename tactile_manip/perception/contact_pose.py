"""Angle, location and force from one reading: the pose estimator and a contact estimator of the same board.

::

    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
    from tactile_manip.perception.contact import ContactEstimator
    from tactile_manip.perception.contact_pose import TactileEstimator

    both = TactileEstimator(TactilePoseEstimator(load_reconstructor("models/supermag.onnx")),
                            ContactEstimator("models/contact_supermag.onnx"))
    est = both.estimate(field_ut)        # -> TactileEstimate
    est.angle.angle_rad, est.contact.position_mm, est.contact.force_n
    for est in both.stream(sensor):      # one TactileEstimate per new frame
        ...

The two run one after the other on the same reading (no shared work: the contact model reads the field, not
the reconstructed image). Each keeps its own contract: the angle may be undefined (``angle.defined``), the
contact's quantities carry their sigmas.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from tactile_manip.perception.contact import ContactEstimator, ContactState
from tactile_manip.perception.estimator import StreamStats, TactilePoseEstimator, stream_estimates
from tactile_manip.types import AngleEstimate, TactileReading

if TYPE_CHECKING:
    from tactile_manip.sensors.base import TactileSensor


@dataclass(frozen=True)
class TactileEstimate:
    """What one reading tells: the in-plane angle (pose estimator) and the contact state (contact model)."""

    angle: AngleEstimate
    contact: ContactState


class TactileEstimator:
    """A :class:`TactilePoseEstimator` and a :class:`ContactEstimator` of the same board, run on each reading.

    Raises ValueError at construction when the two take readings of different shapes or board layouts.
    """

    def __init__(self, pose: TactilePoseEstimator, contact: ContactEstimator) -> None:
        if not isinstance(pose, TactilePoseEstimator):
            raise TypeError(f"pose must be a TactilePoseEstimator, got {type(pose).__name__}")
        if not isinstance(contact, ContactEstimator):
            raise TypeError(f"contact must be a ContactEstimator, got {type(contact).__name__}")
        rec = pose.reconstructor
        if tuple(rec.input_shape) != contact.input_shape or rec.board_layout != contact.board_layout:
            raise ValueError(f"the pose model takes {tuple(rec.input_shape)} readings of the {rec.board_layout!r} "
                             f"board, the contact model {contact.input_shape} of {contact.board_layout!r}: use "
                             "models of one board")
        self.pose = pose
        self.contact = contact

    def estimate(self, reading: TactileReading | np.ndarray) -> TactileEstimate:
        """Angle and contact of ``reading`` (R, C, 3) uT, baseline-subtracted (ValueError for NaN or a wrong
        shape, from either estimator; the contact estimator checks first, so its history stays unchanged)."""
        contact = self.contact.estimate(reading)
        return TactileEstimate(angle=self.pose.estimate(reading), contact=contact)

    def stream(self, sensor: TactileSensor, *, timeout_s: float = 0.1, max_estimates: int | None = None,
               stats: StreamStats | None = None) -> Iterator[TactileEstimate]:
        """One estimate per new frame of ``sensor``, from the newest frame (as the pose estimator's stream)."""
        self.pose.reconstructor.check_layout(sensor.layout.name)
        self.contact.check_layout(sensor.layout.name)
        return stream_estimates(sensor, self.estimate, timeout_s=timeout_s, max_estimates=max_estimates,
                                stats=stats)
