"""The estimator users, behaviours and trial cells take: one reading in; its angle, contact and position out.

:class:`TactileEstimator` joins two parts of the same board: a pose part (the in-plane angle:
:class:`~tactile_manip.perception.estimator.TactilePoseEstimator` over the SuperMag model or an interpolation
baseline, or :class:`~tactile_manip.perception.baselines.BlindPoseEstimator`, which has no tactile input) and,
where the board has one, a contact model (:class:`~tactile_manip.perception.contact.ContactEstimator`: position,
depth and force, each with a sigma). It is the one place where readings are taken from a sensor
(:meth:`TactileEstimator.read`, :meth:`TactileEstimator.stream`); the parts only compute::

    from tactile_manip import TactileEstimator
    est = TactileEstimator.load()                  # the shipped pose model and contact model, from any folder
    e = est.estimate(field_ut)                     # (4, 4, 3) uT -> TactileEstimate
    e.angle.angle_rad, e.position_mm, e.contact.force_n
    e = est.read(sensor, frames=4)                 # the mean of the sensor's next 4 frames (one static contact)
    for e in est.stream(sensor):                   # one TactileEstimate per new frame, always the newest
        ...

Without a contact model (``TactileEstimator(pose)``, ``load(contact_model=None)``) every estimate's ``contact``
is None and ``position_mm`` is the reconstructed contact's centroid. :class:`Estimator` states the interface.

The two parts run one after the other on the same reading (the contact model reads the field, not the image).
Each keeps its own contract: the angle may be undefined (``angle.defined``), the contact's quantities carry their
sigmas, and either may be no answer (``plausible`` False, with its ``implausible_reason``): for a reading beyond
what the chip can report or far beyond the field of a press both are (the same bound: 2000 uT on the SuperMag
board), and a contact state whose output is off the pad or outside the trained force range is.
:attr:`TactileEstimate.plausible` says whether both are answers. Before either part answers, the board's press
check (:mod:`~tactile_manip.perception.press_check`, one for both parts) judges the reading once: within the
board's noise floor it is no contact (:attr:`TactileEstimate.in_contact` False, no position, no force, no
angle), and above it with a pattern no simulated press makes (noise, a uniform field) it is no answer.

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

import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from tactile_manip.perception.estimator import NO_CONTACT_FIELD, _field
from tactile_manip.perception.pose import ISOTROPIC_REASON
from tactile_manip.types import AngleEstimate, Deferred, DeferredField, TactileReading

if TYPE_CHECKING:
    from tactile_manip.perception.contact import ContactEstimator, ContactState
    from tactile_manip.sensors.base import TactileSensor

Reading = TactileReading | np.ndarray  # (R, C, 3) uT, baseline-subtracted


@dataclass
class StreamStats:
    """Counters of one :meth:`TactileEstimator.stream`, updated in place as it runs.

    Attributes:
        estimates: estimates yielded so far.
        skipped_frames: frames between two estimated ones that were never estimated: they arrived while an
            estimate was computed or consumed (the stream then takes the newest frame, not the stale ones
            queued before it), or were lost on the wire (``sensor.health()`` tells those apart).
        last_seq: sequence number of the last estimated frame (None before the first).
    """

    estimates: int = 0
    skipped_frames: int = 0
    last_seq: int | None = None

    def count(self, seq: int) -> None:
        """Record that frame ``seq`` is estimated next (a sequence restart skips nothing)."""
        if self.last_seq is not None:
            self.skipped_frames += max(0, seq - self.last_seq - 1)
        self.last_seq = seq


@dataclass(frozen=True)
class TactileEstimate:
    """What one reading tells: the in-plane angle (the pose part), the contact state (the contact model; None
    without one), and where the contact is from both (``position_mm``, pad frame, mm; None when neither sees a
    contact)."""

    angle: AngleEstimate
    contact: ContactState | None = None
    position_mm: tuple[float, float] | None = DeferredField(None)  # of several pads: measured when first read

    def __getstate__(self) -> dict:
        """The fields with the position measured (a pickled or copied estimate holds values only)."""
        return {**self.__dict__, "_position_mm": self.position_mm}

    @property
    def in_contact(self) -> bool:
        """Whether the reading holds a contact: the contact model's flag where there is one (above the board's
        noise floor: :mod:`~tactile_manip.perception.press_check`), else whether the pose part saw a contact
        field. Without a contact, ``position_mm`` and the contact's quantities are None."""
        if self.contact is not None:
            return self.contact.in_contact
        return self.angle.reason != NO_CONTACT_FIELD

    @property
    def plausible(self) -> bool:
        """Every estimate is an answer (else ``angle.implausible_reason`` or ``contact.implausible_reason`` says
        why not; ``position_mm`` then comes from the other alone, or is None)."""
        return self.angle.plausible and (self.contact is None or self.contact.plausible)


@runtime_checkable
class PoseEstimator(Protocol):
    """The pose part of a :class:`TactileEstimator`: the angle of readings, nothing read from a sensor.

    :class:`~tactile_manip.perception.estimator.TactilePoseEstimator` (a model or an interpolation baseline) and
    :class:`~tactile_manip.perception.baselines.BlindPoseEstimator` implement it.
    """

    def estimate(self, reading: Reading) -> AngleEstimate:
        """The angle of one reading (R, C, 3) uT (ValueError for NaN or a wrong shape)."""

    def estimate_many(self, readings: Sequence[Reading]) -> list[AngleEstimate]:
        """The angles of several pads' readings, each as :meth:`estimate` gives it."""

    def estimate_frames(self, readings: Sequence[Reading]) -> AngleEstimate:
        """The angle of the mean of consecutive readings of one static contact."""

    def check_layout(self, layout: str) -> None:
        """Raise ValueError when a sensor of board layout ``layout`` is not one this part reads."""


@runtime_checkable
class Estimator(Protocol):
    """What a behaviour, a trial cell or a user's loop calls on an estimator: :class:`TactileEstimator`, whatever
    its parts (the shipped model, an interpolation baseline, the blind baseline), implements it.

    Every method returns :class:`TactileEstimate` (``contact`` None without a contact model). ``read`` and
    ``stream`` raise :class:`~tactile_manip.errors.SensorTimeoutError` when the sensor stalls and ValueError when
    its board layout is not the parts'.
    """

    def estimate(self, reading: Reading) -> TactileEstimate:
        """Angle, contact and position of one reading (R, C, 3) uT, baseline-subtracted."""

    def estimate_many(self, readings: Sequence[Reading]) -> list[TactileEstimate]:
        """Each of several pads' readings, as :meth:`estimate` gives it, in batched runs."""

    def read(self, sensor: TactileSensor, *, frames: int = 1, timeout_s: float = 0.1) -> TactileEstimate:
        """The estimate of the mean of the sensor's next ``frames`` new frames."""

    def stream(self, sensor: TactileSensor, *, timeout_s: float = 0.1, max_estimates: int | None = None,
               stats: StreamStats | None = None) -> Iterator[TactileEstimate]:
        """One estimate per new frame of the sensor, always of the newest (stale frames are skipped)."""


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


def fused_position_mm(angle: AngleEstimate, contact: ContactState | None, image_weight: float,
                      min_area_mm2: float = 0.0) -> tuple[float, float] | None:
    """``image_weight`` times the image's centroid plus the rest times the contact model's position; either
    alone where the other has none (the contact model's only while it reports a contact; the image's alone
    without a contact model). None where the reading's field is below the pose estimator's ``min_field_ut``: a
    contact model trained on presses only reports a contact on an empty pad. With no share for the image, the
    contact model's position needs no image (a deferred one stays undecoded)."""
    if angle.reason == NO_CONTACT_FIELD or (contact is not None and not contact.in_contact):
        return None
    model = contact.position_mm if contact is not None and contact.in_contact else None
    if image_weight == 0.0 and model is not None:
        return model
    image = image_centroid_mm(angle, min_area_mm2)
    if image is None or model is None:
        return image or model
    return (image_weight * image[0] + (1.0 - image_weight) * model[0],
            image_weight * image[1] + (1.0 - image_weight) * model[1])


class _LazyPosition(Deferred):
    """The fused position of one pad's estimate, measured when first read (it needs the pad's image, which is
    decoded only then)."""

    __slots__ = ("estimator", "angle", "contact")

    def __init__(self, estimator: TactileEstimator, angle: AngleEstimate, contact: ContactState | None) -> None:
        self.estimator, self.angle, self.contact = estimator, angle, contact

    def resolve(self, name: str) -> tuple[float, float] | None:
        return self.estimator._position(self.angle, self.contact)


class TactileEstimator:
    """The pose part and, where one is given, a contact model of the same board, run on each reading.

    Args:
        pose: the angle's part (:class:`PoseEstimator`).
        contact: the board's contact model, or None (every estimate's ``contact`` is then None).
        image_position_weight: the reconstructed image's share in :attr:`TactileEstimate.position_mm`; None takes
            the contact model's (its ``image_position_weight``, 0 where its file has none; 1 without a model).

    Raises ValueError at construction when the two take readings of different shapes or board layouts, or for a
    weight outside [0, 1]; TypeError for a part that is not one.
    """

    def __init__(self, pose: PoseEstimator, contact: ContactEstimator | None = None, *,
                 image_position_weight: float | None = None) -> None:
        if image_position_weight is not None and not (
                isinstance(image_position_weight, (int, float)) and 0.0 <= image_position_weight <= 1.0):
            raise ValueError(f"image_position_weight must be a share in [0, 1], got {image_position_weight!r}")
        if not isinstance(pose, PoseEstimator):
            raise TypeError(f"pose must be a pose estimator (estimate, estimate_many, estimate_frames, "
                            f"check_layout), got {type(pose).__name__}")
        if contact is not None:
            from tactile_manip.perception.contact import ContactEstimator

            if not isinstance(contact, ContactEstimator):
                raise TypeError(f"contact must be a ContactEstimator or None, got {type(contact).__name__}")
            shape, layout = getattr(pose, "input_shape", None), getattr(pose, "board_layout", "")
            if shape is not None and (tuple(shape) != contact.input_shape or layout != contact.board_layout):
                raise ValueError(f"the pose model takes {tuple(shape)} readings of the {layout!r} board, the "
                                 f"contact model {contact.input_shape} of {contact.board_layout!r}: use models of "
                                 "one board")
            pose_metadata = getattr(getattr(pose, "reconstructor", None), "metadata", None)
            if isinstance(pose_metadata, dict):  # the same name may still be two boards: their identities tell
                from tactile_manip.boards.identity import check_same_board, record_of_metadata

                check_same_board("the pose model", record_of_metadata(pose_metadata), "the contact model",
                                 record_of_metadata(contact.metadata))
        self.pose = pose
        self.contact = contact
        default = 1.0 if contact is None else contact.image_position_weight
        self.image_position_weight = float(default if image_position_weight is None else image_position_weight)
        self._min_area_mm2 = float(getattr(pose, "min_contact_area_mm2", 0.0))

    @classmethod
    def load(cls, pose_model: str | Path | None = "supermag", contact_model: str | Path | None = "contact", *,
             image_position_weight: float | None = None, **options: Any) -> TactileEstimator:
        """An estimator from its model files, in one call: by default the shipped pose model
        (``models/supermag.onnx``) and contact model (``models/contact_supermag.onnx``), found from any working
        folder. ``pose_model``: a shipped model's name, an ``.onnx`` path, ``"bilinear"``, ``"bicubic"`` or
        ``"blind"``, or None (a board with a contact model alone: no angle); ``contact_model``: a name, a path or
        None; ``options``: the pose part's (threads, samples,
        image_symmetry, angle_source, calibrated, ...). See :func:`~tactile_manip.perception.loading.load_estimator`.

        Raises:
            ModelFileError: a file is missing (the message says where it looked) or not a model of its kind.
            ValueError: the two models read different boards, or an option is out of its range.
        """
        from tactile_manip.perception.loading import load_estimator

        return load_estimator(pose_model, contact_model, image_position_weight=image_position_weight, **options)

    def __repr__(self) -> str:
        return f"TactileEstimator(pose={self.pose!r}, contact={self.contact!r})"

    def _position(self, angle: AngleEstimate, contact: ContactState | None) -> tuple[float, float] | None:
        return fused_position_mm(angle, contact, self.image_position_weight, self._min_area_mm2)

    def set_noise_floor(self, noise_ut: np.ndarray) -> None:
        """Judge "no contact" against a measured noise floor in both parts: ``noise_ut`` (3,) per axis or (R, C, 3)
        per channel, uT, such as a sensor's ``baseline.noise_ut`` (with the drift allowance, never below the
        board's rated floor: :meth:`~tactile_manip.perception.press_check.PressCheck.with_noise`)."""
        checks = [part for part in (self.pose, self.contact) if getattr(part, "press_check", None) is not None]
        if checks:  # one check for both parts, as loaded: the reading is judged once
            check = checks[0].press_check.with_noise(noise_ut)
            for part in checks:
                part.press_check = check

    def check_layout(self, layout: str) -> None:
        """Refuse a sensor of board layout ``layout`` that either part does not read (ValueError naming both)."""
        self.pose.check_layout(layout)
        if self.contact is not None:
            self.contact.check_layout(layout)

    def estimate(self, reading: Reading) -> TactileEstimate:
        """Angle, contact and position of ``reading`` (R, C, 3) uT, baseline-subtracted (ValueError for NaN or
        a wrong shape, from either part; the contact model checks first, so its history stays unchanged). As in
        :meth:`estimate_many`, the position is measured when first read: where the angle comes from the head, the
        image it needs is decoded only then."""
        contact = self.contact.estimate(reading) if self.contact is not None else None
        angle = self.pose.estimate(reading)
        return TactileEstimate(angle=angle, contact=contact, position_mm=_LazyPosition(self, angle, contact))

    def estimate_many(self, readings: Sequence[Reading]) -> list[TactileEstimate]:
        """Angle, contact and position of several pads' readings (each (R, C, 3) uT): the angles in one batched
        run (:meth:`TactilePoseEstimator.estimate_many`, images deferred where the head answers), the contact
        states in another (:meth:`ContactEstimator.estimate_many`, each reading alone). A position is measured
        on a pad's image only when it is read.

        Raises:
            ValueError: a contact model that reads frames before the newest (its context is one pad's history:
                use one TactileEstimator per pad), or a bad reading (nothing is estimated).
        """
        if self.contact is not None and self.contact.context_frames != 1:
            raise ValueError(f"{self.contact.path.name} reads {self.contact.context_frames} frames of one pad's "
                             "history; estimate_many mixes pads: use one TactileEstimator per pad")
        angles = self.pose.estimate_many(readings)  # checks every reading (shape, NaN) before estimating any
        contacts = self.contact.estimate_many(readings) if self.contact is not None else [None] * len(angles)
        return [TactileEstimate(angle=a, contact=c, position_mm=_LazyPosition(self, a, c))
                for a, c in zip(angles, contacts)]

    def estimate_frames(self, readings: Sequence[Reading]) -> TactileEstimate:
        """Angle, contact and position from the mean of consecutive readings of one static contact (less chip
        noise). The contact model reads the mean as one reading with no context before it (its history is
        reset), so an earlier grasp never leaks into this one."""
        if len(readings) == 0:
            raise ValueError("estimate_frames needs at least one reading")
        contact = None
        if self.contact is not None:
            fields = [np.asarray(_field(r)) for r in readings]
            if len({f.shape for f in fields}) != 1:
                raise ValueError("readings of different shapes cannot be averaged: "
                                 f"{sorted({f.shape for f in fields})}")
            last = readings[-1]
            self.contact.reset()
            contact = self.contact.estimate(np.mean(np.stack(fields).astype(np.float64), axis=0),
                                            t_s=last.t_host_s if isinstance(last, TactileReading) else None)
        angle = self.pose.estimate_frames(readings)
        return TactileEstimate(angle=angle, contact=contact, position_mm=self._position(angle, contact))

    def read(self, sensor: TactileSensor, *, frames: int = 1, timeout_s: float = 0.1) -> TactileEstimate:
        """Estimate from the next ``frames`` new frames of ``sensor`` (:meth:`estimate_frames`; frames that
        arrived before the call are not used, so a contact made just before is seen as it is now).

        Raises:
            SensorTimeoutError: a frame did not arrive within ``timeout_s`` (a stalled sensor).
            ValueError: ``frames`` is not a positive integer, or the sensor's board layout is not the parts'.
        """
        if isinstance(frames, bool) or not isinstance(frames, int) or frames < 1:
            raise ValueError(f"frames must be a positive integer, got {frames!r}")
        self.check_layout(sensor.layout)
        return self.estimate_frames(_fresh_frames(sensor, frames, timeout_s))

    def stream(self, sensor: TactileSensor, *, timeout_s: float = 0.1, max_estimates: int | None = None,
               stats: StreamStats | None = None) -> Iterator[TactileEstimate]:
        """Yield one estimate per new frame of ``sensor``, at the sensor's rate, always from the newest frame.

        Frames that arrive while an estimate is computed (or while the caller holds the previous one) are
        skipped, not queued, so the stream never falls behind. ``stats`` (a :class:`StreamStats`), when given,
        counts the estimates and the skipped frames as the stream runs. Stops after ``max_estimates`` (None:
        never).

        Raises:
            SensorTimeoutError: the sensor stalls.
            ValueError: the sensor's board layout is not the parts' (before the first frame is read).
        """
        self.check_layout(sensor.layout)
        return _stream(sensor, self.estimate, timeout_s, max_estimates,
                       StreamStats() if stats is None else stats)


def _stream(sensor: TactileSensor, estimate, timeout_s: float, max_estimates: int | None,
            stats: StreamStats) -> Iterator[TactileEstimate]:
    count = 0
    while max_estimates is None or count < max_estimates:
        reading = sensor.wait_new(timeout_s)  # the newest frame not returned before
        stats.count(reading.seq)
        est = estimate(reading)
        stats.estimates += 1
        count += 1
        yield est


def _fresh_frames(sensor: TactileSensor, frames: int, timeout_s: float) -> list[TactileReading]:
    """``frames`` consecutive readings that arrived after this call, oldest first."""
    start_s = time.monotonic()
    readings: list[TactileReading] = []
    while len(readings) < frames:
        reading = sensor.wait_new(timeout_s)
        if reading.t_host_s >= start_s:
            readings.append(reading)
    return readings
