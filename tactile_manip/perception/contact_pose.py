"""Angle, location and force from one reading: the pose estimator and a contact estimator of the same board.

::

    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
    from tactile_manip.perception.contact import ContactEstimator
    from tactile_manip.perception.contact_pose import TactileEstimator

    both = TactileEstimator(TactilePoseEstimator(load_reconstructor("models/supermag.onnx")),
                            ContactEstimator("models/contact_supermag.onnx"))
    est = both.estimate(field_ut)        # -> TactileEstimate
    est.angle.angle_rad, est.position_mm, est.contact.force_n
    est = both.read(sensor, frames=4)    # the mean of the sensor's next 4 frames (one static contact)
    for est in both.stream(sensor):      # one TactileEstimate per new frame
        ...

The two run one after the other on the same reading (the contact model reads the field, not the reconstructed
image). Each keeps its own contract: the angle may be undefined (``angle.defined``), the contact's quantities
carry their sigmas, and either may be no answer (``plausible`` False, with its ``implausible_reason``): for a
reading beyond what the chip can report or far beyond the field of a press both are (the same bound: 2000 uT on
the SuperMag board), and a contact state whose output is off the pad or outside the trained force range is.
:attr:`TactileEstimate.plausible` says whether both are answers.

Where the contact is, two estimates exist: the centroid of the reconstructed contact (``angle.centroid_mm``)
and the contact model's centre of pressure (``contact.position_mm``). They err differently: on objects neither
model was trained on, the image's centroid is the better one and their weighted mean better than either
(``benchmarks/contact_position_fusion.py``), while a model trained on the one probe it presses beats the image.
``position_mm`` is that mean, with the image's share ``image_position_weight``: by default the one stored in the
contact model (``export --image-position-weight``, chosen on validation presses; 0.5 for the shipped
``models/contact_supermag.onnx``), else 0 (the contact model's position). It falls back on whichever of the
two exists (an implausible estimate gives none).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from tactile_manip.perception.contact import ContactEstimator, ContactState
from tactile_manip.perception.estimator import (NO_CONTACT_FIELD, StreamStats, TactilePoseEstimator, _field,
                                                 _fresh_frames, stream_estimates)
from tactile_manip.perception.pose import ISOTROPIC_REASON
from tactile_manip.types import AngleEstimate, Deferred, DeferredField, TactileReading

if TYPE_CHECKING:
    from tactile_manip.sensors.base import TactileSensor


@dataclass(frozen=True)
class TactileEstimate:
    """What one reading tells: the in-plane angle (pose estimator), the contact state (contact model), and where
    the contact is from both (``position_mm``, pad frame, mm; None when neither sees a contact)."""

    angle: AngleEstimate
    contact: ContactState
    position_mm: tuple[float, float] | None = DeferredField(None)  # of several pads: measured when first read

    def __getstate__(self) -> dict:
        """The fields with the position measured (a pickled or copied estimate holds values only)."""
        return {**self.__dict__, "_position_mm": self.position_mm}

    @property
    def plausible(self) -> bool:
        """Both estimates are answers (else ``angle.implausible_reason`` or ``contact.implausible_reason`` says
        why not; ``position_mm`` then comes from the other alone, or is None)."""
        return self.angle.plausible and self.contact.plausible


def image_centroid_mm(angle: AngleEstimate, min_area_mm2: float = 0.0) -> tuple[float, float] | None:
    """The reconstructed contact's centroid, where the image holds a contact of at least ``min_area_mm2`` (the
    pose estimator's smallest, :attr:`TactilePoseEstimator.min_contact_area_mm2`), else None.

    An isotropic contact has a centroid but no angle. An estimate whose angle came from the angle head is
    defined even where the image's contact is too small to have a centroid; its area tells.
    """
    if angle.area_mm2 <= 0.0 or angle.area_mm2 < min_area_mm2:
        return None
    if angle.defined or angle.reason.startswith(ISOTROPIC_REASON):
        return angle.centroid_mm
    return None


def fused_position_mm(angle: AngleEstimate, contact: ContactState, image_weight: float,
                      min_area_mm2: float = 0.0) -> tuple[float, float] | None:
    """``image_weight`` times the image's centroid plus the rest times the contact model's position; either
    alone where the other has none (the contact model's only while it reports a contact). None where the
    reading's field is below the pose estimator's ``min_field_ut``: a contact model trained on presses only
    reports a contact on an empty pad. With no share for the image, the contact model's position needs no image
    (a deferred one stays undecoded)."""
    if angle.reason == NO_CONTACT_FIELD:
        return None
    model = contact.position_mm if contact.in_contact else None
    if image_weight == 0.0 and model is not None:
        return model
    image = image_centroid_mm(angle, min_area_mm2)
    if image is None or model is None:
        return image or model
    return (image_weight * image[0] + (1.0 - image_weight) * model[0],
            image_weight * image[1] + (1.0 - image_weight) * model[1])


class _LazyPosition(Deferred):
    """The fused position of one pad of :meth:`TactileEstimator.estimate_many`, measured when first read (it
    needs the pad's image, which is decoded only then)."""

    __slots__ = ("estimator", "angle", "contact")

    def __init__(self, estimator: TactileEstimator, angle: AngleEstimate, contact: ContactState) -> None:
        self.estimator, self.angle, self.contact = estimator, angle, contact

    def resolve(self, name: str) -> tuple[float, float] | None:
        e = self.estimator
        return fused_position_mm(self.angle, self.contact, e.image_position_weight, e.pose.min_contact_area_mm2)


class TactileEstimator:
    """A :class:`TactilePoseEstimator` and a :class:`ContactEstimator` of the same board, run on each reading.

    ``image_position_weight``: the reconstructed image's share in :attr:`TactileEstimate.position_mm`; None
    takes the contact model's (its ``image_position_weight``, 0 where its file has none).

    Raises ValueError at construction when the two take readings of different shapes or board layouts, or for a
    weight outside [0, 1].
    """

    def __init__(self, pose: TactilePoseEstimator, contact: ContactEstimator, *,
                 image_position_weight: float | None = None) -> None:
        if image_position_weight is not None and not (
                isinstance(image_position_weight, (int, float)) and 0.0 <= image_position_weight <= 1.0):
            raise ValueError(f"image_position_weight must be a share in [0, 1], got {image_position_weight!r}")
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
        self.image_position_weight = float(contact.image_position_weight if image_position_weight is None
                                           else image_position_weight)

    def estimate(self, reading: TactileReading | np.ndarray) -> TactileEstimate:
        """Angle, contact and position of ``reading`` (R, C, 3) uT, baseline-subtracted (ValueError for NaN or
        a wrong shape, from either estimator; the contact estimator checks first, so its history stays
        unchanged)."""
        contact = self.contact.estimate(reading)
        angle = self.pose.estimate(reading)
        return TactileEstimate(angle=angle, contact=contact,
                               position_mm=fused_position_mm(angle, contact, self.image_position_weight,
                                                             self.pose.min_contact_area_mm2))

    def estimate_many(self, readings) -> list[TactileEstimate]:
        """Angle, contact and position of several pads' readings (each (R, C, 3) uT): the angles in one batched
        run (:meth:`TactilePoseEstimator.estimate_many`, images deferred where the head answers), the contact
        states in another (:meth:`ContactEstimator.estimate_many`, each reading alone). A position is measured
        on a pad's image only when it is read.

        Raises:
            ValueError: a contact model that reads frames before the newest (its context is one pad's history:
                use one TactileEstimator per pad), or a bad reading (nothing is estimated).
        """
        if self.contact.context_frames != 1:
            raise ValueError(f"{self.contact.path.name} reads {self.contact.context_frames} frames of one pad's "
                             "history; estimate_many mixes pads: use one TactileEstimator per pad")
        angles = self.pose.estimate_many(readings)  # checks every reading (shape, NaN) before estimating any
        contacts = self.contact.estimate_many(readings)
        return [TactileEstimate(angle=a, contact=c, position_mm=_LazyPosition(self, a, c)) for a, c in
                zip(angles, contacts)]

    def estimate_frames(self, readings) -> TactileEstimate:
        """Angle, contact and position from the mean of consecutive readings of one static contact (less chip
        noise). The contact model reads the mean as one reading with no context before it (its history is
        reset), so an earlier grasp never leaks into this one."""
        if len(readings) == 0:
            raise ValueError("estimate_frames needs at least one reading")
        fields = [np.asarray(_field(r)) for r in readings]
        if len({f.shape for f in fields}) != 1:
            raise ValueError(f"readings of different shapes cannot be averaged: {sorted({f.shape for f in fields})}")
        last = readings[-1]
        self.contact.reset()
        contact = self.contact.estimate(np.mean(np.stack(fields).astype(np.float64), axis=0),
                                        t_s=last.t_host_s if isinstance(last, TactileReading) else None)
        angle = self.pose.estimate_frames(readings)
        return TactileEstimate(angle=angle, contact=contact,
                               position_mm=fused_position_mm(angle, contact, self.image_position_weight,
                                                             self.pose.min_contact_area_mm2))

    def read(self, sensor: TactileSensor, *, frames: int = 1, timeout_s: float = 0.1) -> TactileEstimate:
        """Estimate from the next ``frames`` new frames of ``sensor`` (:meth:`estimate_frames`; frames that
        arrived before the call are not used).

        Raises:
            SensorTimeoutError: a frame did not arrive within ``timeout_s`` (a stalled sensor).
        """
        if isinstance(frames, bool) or not isinstance(frames, int) or frames < 1:
            raise ValueError(f"frames must be a positive integer, got {frames!r}")
        self.pose.reconstructor.check_layout(sensor.layout.name)
        self.contact.check_layout(sensor.layout.name)
        return self.estimate_frames(_fresh_frames(sensor, frames, timeout_s))

    def stream(self, sensor: TactileSensor, *, timeout_s: float = 0.1, max_estimates: int | None = None,
               stats: StreamStats | None = None) -> Iterator[TactileEstimate]:
        """One estimate per new frame of ``sensor``, from the newest frame (as the pose estimator's stream)."""
        self.pose.reconstructor.check_layout(sensor.layout.name)
        self.contact.check_layout(sensor.layout.name)
        return stream_estimates(sensor, self.estimate, timeout_s=timeout_s, max_estimates=max_estimates,
                                stats=stats)
