"""The pose part of an estimator: one magnetic reading in, the contact's in-plane angle out.

:class:`TactilePoseEstimator` composes a :class:`~tactile_manip.perception.reconstruct.Reconstructor`
(SuperMag ONNX model or an interpolation baseline) with the paper's post-processing and PCA
(:func:`~tactile_manip.perception.pose.angle_from_image`). It takes a (4, 4, 3) reading (an array in
microtesla or a :class:`~tactile_manip.types.TactileReading`) and returns an
:class:`~tactile_manip.types.AngleEstimate` with angle, confidence, defined flag, contact centroid and area,
and per-stage timings. It can average several consecutive frames (:meth:`TactilePoseEstimator.estimate_frames`)
and estimate several pads' readings in one batched model run (:meth:`TactilePoseEstimator.estimate_many`).
It reads no sensor: users, behaviours and trial cells take the
:class:`~tactile_manip.perception.tactile_estimator.TactileEstimator` it is the pose part of, whose ``read``
and ``stream`` take frames from any :class:`~tactile_manip.sensors.base.TactileSensor`::

    from tactile_manip import TactileEstimator
    estimator = TactileEstimator.load(contact_model=None)     # the shipped pose model alone
    pose = estimator.pose                                     # this class
    left, right = pose.estimate_many([left_reading, right_reading])   # two pads, one model run

Confidence: the PCA's ``1 - lambda_minor / lambda_major``; when the reconstructor draws several prior samples
(``OnnxReconstructor(samples=K)``), it is multiplied by the samples' agreement on the contact,
``clip(1 - mean(spread) / mean(depth), 0, 1)`` over the contact pixels; and when channels are saturated (a
:class:`~tactile_manip.types.TactileReading` flags a chip at its ADC rail, or any reading, array or not, holds
a value beyond the chip's full scale, which every reconstructor clamps: see
:func:`~tactile_manip.perception.reconstruct.out_of_range`), by the fraction of chips with no saturated axis.
The estimate's ``saturated_chips`` counts those chips. With a ``calibration``
(:class:`~tactile_manip.perception.confidence.ConfidenceCalibration`), that raw confidence is finally mapped
onto the probability, measured on held-out presses, that the angle is within the calibration's tolerance.

Extra inference only when it is needed: with an ``escalation`` reconstructor (e.g. the same model averaged over
the sensor's symmetries, :class:`~tactile_manip.perception.symmetry.SymmetrizedReconstructor`, or drawing K
prior samples) and ``escalate_below``, an estimate whose (calibrated) confidence is below that level is made
again from the same reading by the escalation reconstructor; that estimate replaces the first
(``escalated=True``, its cost in ``timings_s["escalate"]``)::

    model = load_reconstructor("models/supermag.onnx")
    estimator = TactilePoseEstimator(model, calibration=load_calibration_beside("models/supermag.onnx"),
                                     escalation=SymmetrizedReconstructor(model), escalate_below=0.5)

The escalated estimate replaces the first whatever its confidence, which the same calibration maps (it was
fitted on the one-pass estimator, so for the escalated one it is an approximation); a contact whose angle is
undefined (confidence 0) escalates too. Only an angle read from the image escalates: with the angle head's
route, that is where the head stood aside (a chip flagged saturated, an image without contact).

No answer is silently wrong. A reading with a |value| at or beyond :attr:`TactilePoseEstimator.plausible_limits_ut`
is implausible: more than an MLX90393 can report as a change (:data:`CHANGE_LIMIT_UT`, twice its full scale), or
far beyond the field of any press the model was made for (the model's ``input.plausible_field_ut``, else its
board's :data:`PLAUSIBLE_FIELD_UT`: 2000 uT on the SuperMag board, where no simulated press of a rod or bar
comes near). Its estimate is no answer: ``plausible`` False, ``implausible_reason`` naming the chip, the value
and the bound, ``defined`` False, angle and confidence 0.0, ``reason`` "implausible reading"; it does not
escalate. A plausible reading's estimate is what it was before the check (the check is one comparison of the
reading's largest |value|, which the no-contact rule computes anyway). NaN and infinite values still raise
ValueError. A chip flagged saturated (at its ADC rail, or beyond the chip's full scale in a reading whose bound
is higher) caps the confidence after the calibration at :data:`SATURATED_CONFIDENCE_CAP` times the fraction of
chips without: the calibration was fitted on readings without one, and a railed value is a bound, not a
measurement; escalation goes through the same cap.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from tactile_manip.perception.confidence import ConfidenceCalibration
from tactile_manip.perception.angle_head import within_probability
from tactile_manip.perception.pose import PoseParams, angle_from_image, wrap_axial
from tactile_manip.perception.press_check import PressCheck, press_check_for
from tactile_manip.perception.reconstruct import (READING_LIMIT_UT, ModelFileError, Reconstruction, Reconstructor,
                                                   out_of_range)
from tactile_manip.types import IMPLAUSIBLE_READING, AngleEstimate, Deferred, TactileReading

ANGLE_SOURCES = ("auto", "image", "head", "likelier")
NO_CONTACT_FIELD = "no contact field"  # the reason of a reading whose field is below the estimator's min_field_ut
#: with a chip flagged saturated, the (calibrated) confidence is at most this times the fraction of chips without:
#: below every ``min_confidence`` a shipped scene or behaviour acts on (0.3, 0.8)
SATURATED_CONFIDENCE_CAP = 0.1
#: (3,) uT: the largest change per axis (x, y, z) a baseline-subtracted MLX90393 reading can hold (its raw value
#: and its no-contact baseline each lie within the chip's full scale)
CHANGE_LIMIT_UT = 2.0 * READING_LIMIT_UT
#: uT, per board layout: a reading with a |value| at or beyond this is implausible for a model that stores no
#: bound of its own (``input.plausible_field_ut`` in its metadata). SuperMag board, 2000 uT: simulated presses of
#: rods and bars (the objects of every angle figure, the calibration and the trials) on drawn sensors at 2-15 N
#: peak at 1179 uT (2300 presses), and at 1748 uT at the strongest corner of the randomisation ranges (0.055 T,
#: 0.8 mm gap, the softest skin, 15 N); one chip set to 2000-5000 uT in a rod's press turned the angle head's
#: answer by 55-85 deg at confidence 0.95-1.0. Of 4738 presses drawn as the training and test sets are, 56 reach
#: it: 51 pressed through the whole skin (flagged bottomed out: the elastic model ends there and the image
#: model's training drops them) and 5 sharp tips at 2-3 N right above one chip.
PLAUSIBLE_FIELD_UT: dict[str, float] = {"supermag-4x4": 2000.0}


class TactilePoseEstimator:
    """Reconstructor + post-processing + PCA (see the module docstring).

    Args:
        reconstructor: turns a reading into a depth image (mm).
        params: post-processing and PCA parameters (defaults: the paper's pipeline as tuned in
            :class:`~tactile_manip.perception.pose.PoseParams`).
        min_field_ut: a reading whose largest |field change| is below this is "no contact" whatever the
            reconstruction shows (0: trust the image). Chip noise peaks near 10 uT on the simulated pad and a
            10 N press gives 95 uT and more; a model never trained on empty readings may otherwise draw a
            faint contact into one (the fast reference model draws 0.40 mm into an all-zero reading).
        calibration: maps the raw confidence of a defined estimate onto the probability that its angle is
            within the calibration's tolerance, fitted on held-out presses
            (:class:`~tactile_manip.perception.confidence.ConfidenceCalibration`); None keeps the raw one.
        angle_source: where the angle comes from (the estimate's ``source`` says which it was): "auto" (the
            default) reads it with the model's angle head when its file has one, else from the image; "image"
            the principal axis of the reconstruction; "head" the angle head (refused for a model without one);
            "likelier" whichever of the two is the more likely within tolerance (the image's probability is its
            calibrated confidence). See :meth:`_with_head`.
    """

    def __init__(self, reconstructor: Reconstructor, params: PoseParams | None = None, *,
                 min_field_ut: float = 20.0, calibration: ConfidenceCalibration | None = None,
                 escalation: Reconstructor | None = None, escalate_below: float = 0.0,
                 angle_source: str = "auto") -> None:
        if not isinstance(reconstructor, Reconstructor):
            raise TypeError(f"reconstructor must be a Reconstructor, got {type(reconstructor).__name__}")
        if not (np.isfinite(min_field_ut) and min_field_ut >= 0):
            raise ValueError(f"min_field_ut must be a finite value >= 0, got {min_field_ut!r}")
        self.reconstructor = reconstructor
        self.params = params or PoseParams()
        self.min_field_ut = float(min_field_ut)
        if calibration is not None and not isinstance(calibration, ConfidenceCalibration):
            raise TypeError(f"calibration must be a ConfidenceCalibration, got {type(calibration).__name__}")
        self.calibration = calibration
        if escalation is not None and not isinstance(escalation, Reconstructor):
            raise TypeError(f"escalation must be a Reconstructor, got {type(escalation).__name__}")
        if not (np.isfinite(escalate_below) and 0.0 <= escalate_below <= 1.0):
            raise ValueError(f"escalate_below must be a confidence in [0, 1], got {escalate_below!r}")
        if escalation is not None:
            def io(r: Reconstructor) -> tuple:
                return (tuple(r.input_shape), tuple(r.output_shape), r.pixel_mm, r.board_layout, r.magnetic_ut)

            if io(escalation) != io(reconstructor):
                raise ValueError(f"escalation {escalation.name} maps (input shape, output shape, mm/px, board layout, "
                                 f"readings in uT) {io(escalation)}, {reconstructor.name} {io(reconstructor)}: they "
                                 "must match")
        self.escalation = escalation
        self.escalate_below = float(escalate_below)
        if angle_source not in ANGLE_SOURCES:
            raise ValueError(f"angle_source must be one of {', '.join(ANGLE_SOURCES)}, got {angle_source!r}")
        head = getattr(reconstructor, "angle_head", None)
        if angle_source == "head" and head is None:
            raise ValueError(f"angle_source 'head': {reconstructor.name} has no angle head (attach one with "
                             "`tactile-manip export --checkpoint RUN/best.pt --attach-to MODEL`)")
        #: "image", "head" or "likelier": the route this estimator's angles take ("auto" resolved)
        self.angle_source = ("head" if head is not None else "image") if angle_source == "auto" else angle_source
        #: the model's angle head when the estimator uses it, else None
        self.angle_head = head if self.angle_source != "image" else None
        if calibration is not None and calibration.route != self.angle_source:
            raise ValueError(f"the calibration was fitted for angles from the {calibration.route!r} route, this "
                             f"estimator's come from {self.angle_source!r}: fit one for it (`tactile-manip "
                             "calibrate`) or give angle_source to match")
        self._tolerance_rad = math.radians(calibration.tolerance_deg if calibration is not None else 5.0)
        #: (channels,) uT: a reading with a |value| at or beyond its channel's limit is implausible (no answer)
        self.plausible_limits_ut = plausible_limits_ut(
            _model_metadata(reconstructor), channels=int(reconstructor.input_shape[-1]),
            board_layout=reconstructor.board_layout, magnetic_ut=reconstructor.magnetic_ut)
        self._plausible_ut = float(self.plausible_limits_ut.min())  # below it, one comparison says "plausible"
        #: the board's no-contact and press-likeness tests (None for a reconstructor of no known board, such as
        #: the interpolation baselines: the field rule ``min_field_ut`` alone decides there)
        self.press_check: PressCheck | None = (
            press_check_for(reconstructor.board_layout, tuple(reconstructor.input_shape))
            if reconstructor.magnetic_ut and _model_metadata(reconstructor) else None)

    @property
    def input_shape(self) -> tuple[int, ...]:
        """(R, C, A): the shape of a reading this estimator takes (its reconstructor's)."""
        return tuple(self.reconstructor.input_shape)

    @property
    def board_layout(self) -> str:
        """The board layout of the readings this estimator takes ("" for any: the interpolation baselines)."""
        return self.reconstructor.board_layout

    def check_layout(self, layout: str) -> None:
        """Refuse a sensor of another board layout than the reconstructor's (ValueError naming both)."""
        self.reconstructor.check_layout(layout)

    def __repr__(self) -> str:
        return f"TactilePoseEstimator({self.reconstructor.name!r}, angle_source={self.angle_source!r})"

    @property
    def min_contact_area_mm2(self) -> float:
        """The smallest contact the image route measures (``params.min_contact_px`` pixels): an estimate's
        ``area_mm2`` below it holds no centroid, even where the angle head defined its angle."""
        return self.params.min_contact_px * self.reconstructor.pixel_mm ** 2

    @property
    def name(self) -> str:
        """The reconstructor's name (e.g. "supermag", "bilinear")."""
        return self.reconstructor.name

    def implausible(self, field_ut: np.ndarray) -> str:
        """Why the reading(s) ``field_ut`` (..., R, C, 3) uT are implausible for this estimator (a |value| at or
        beyond :attr:`plausible_limits_ut`, or NaN), "" when they are not."""
        return implausible_field(field_ut, self.plausible_limits_ut, magnetic_ut=self.reconstructor.magnetic_ut)

    def estimate(self, reading: TactileReading | np.ndarray) -> AngleEstimate:
        """Angle of the contact in one reading (R, C, 3), microtesla, baseline-subtracted. An implausible reading
        (a |value| at or beyond :attr:`plausible_limits_ut`) gives no answer: ``plausible`` False, ``defined``
        False, confidence 0.0 (see the module docstring). Where the angle head answers, the image is decoded only
        when the estimate's ``centroid_mm`` or ``area_mm2`` is first read.

        Raises:
            ValueError: wrong shape, or NaN / infinite values in the reading (from the reconstructor).
        """
        t0 = time.perf_counter()
        return self._estimates([_field(reading)], [_saturated(reading)], [_dated(reading)], t0)[0][0]

    def estimate_with_image(self, reading: TactileReading | np.ndarray) -> tuple[AngleEstimate, Reconstruction]:
        """Like :meth:`estimate`, also returning the reconstruction (depth and spread): the image is decoded
        now, whichever route the angle takes (for a display)."""
        t0 = time.perf_counter()
        estimates, recs = self._estimates([_field(reading)], [_saturated(reading)], [_dated(reading)], t0,
                                          images=True)
        return estimates[0], recs[0]

    def estimate_many(self, readings: Sequence[TactileReading | np.ndarray]) -> list[AngleEstimate]:
        """Angles of several readings (e.g. the pads of a hand), in one batched model run per stage.

        Each estimate equals what :meth:`estimate` returns for its reading. Where the angle head answers, one
        batched run of the head gives every such pad's angle, and their images are decoded together, in one
        batched run, only when a centroid or an area of one of them is first read. Readings whose angle comes
        from the image (no head, a flagged chip, ``angle_source`` "image" or "likelier") are reconstructed in
        one batched run. In ``timings_s``, "head" and "reconstruct" are the whole batch's time for its stage and
        "total" runs from the call to that estimate's completion. An estimate that escalates runs its escalation
        on its own reading, after the batch.

        Raises:
            ValueError: readings of different shapes, or any with NaN / infinite values (nothing is estimated).
        """
        t0 = time.perf_counter()
        if len(readings) == 0:
            return []
        return self._estimates([_field(r) for r in readings], [_saturated(r) for r in readings],
                               [_dated(r) for r in readings], t0)[0]

    @property
    def defers_images(self) -> bool:
        """Whether estimates whose angle the head gives leave their image undecoded until it is read (the head's
        route on a deterministic reconstructor: one whose image of a reading is always the same)."""
        return self.angle_source == "head" and getattr(self.reconstructor, "deterministic", False)

    def _estimates(self, fields: list, saturated: list, dated: list, t0: float, *, why: list[str] | None = None,
                   images: bool = False) -> tuple[list[AngleEstimate], list[Reconstruction] | None]:
        """The estimates of readings ``fields`` (each (R, C, 3) uT) with their sensor flags (or None) and the
        frames that date them (or None); ``why``: whether each is implausible, judged by the caller (None: judge
        each field here). With ``images`` every image is decoded now and returned beside the estimates."""
        shapes = {np.shape(f) for f in fields}
        if len(shapes) != 1:
            raise ValueError(f"estimate_many: readings of different shapes: {sorted(shapes)}")
        stack = np.stack([np.asarray(f, dtype=np.float64) for f in fields])
        # refuses NaN / inf and wrong shapes before anything (a single reading's error names its own index)
        checked = (self.reconstructor.checked(stack[0])[None] if len(stack) == 1
                   else self.reconstructor.checked_many(stack))
        flags = out_of_range(stack)
        for i, sat in enumerate(saturated):
            if sat is not None:
                flags[i] |= np.asarray(sat, dtype=bool)
        n = len(stack)
        peaks = np.abs(stack).reshape(n, -1).max(axis=1)
        flagged = flags.reshape(n, -1).any(axis=1)
        contact, no_press = self._judge(stack, peaks)
        out: list[AngleEstimate | None] = [None] * n
        now, later = [], []  # readings whose image is needed now; those whose head answers
        for i in range(n):
            reason = why[i] if why is not None else (self.implausible(stack[i]) if peaks[i] >= self._plausible_ut
                                                     else "")
            reason = reason or no_press[i]
            if reason:  # no answer: nothing to escalate (an image only where the caller asked for it)
                out[i] = AngleEstimate(0.0, 0.0, False, reason=IMPLAUSIBLE_READING, plausible=False,
                                       implausible_reason=reason)
                if images:
                    now.append(i)
            elif not contact[i] and not images:
                out[i] = AngleEstimate(0.0, 0.0, False, reason=NO_CONTACT_FIELD)
            elif self.defers_images and not flagged[i] and not images and contact[i]:
                later.append(i)
            else:
                now.append(i)
        timings: list[dict[str, float]] = [{} for _ in range(n)]
        recs: list[Reconstruction | None] = [None] * n
        if later:
            t1 = time.perf_counter()
            angles, kappas = self.angle_head.axes(checked[later])
            p = within_probability(kappas, self._tolerance_rad)
            if self.calibration is not None:
                p = self.calibration(p)
            pending = _PendingImages(self, checked[later])
            head_s = time.perf_counter() - t1
            for j, i in enumerate(later):
                stat = _PendingStat(pending, j)
                out[i] = AngleEstimate(float(wrap_axial(angles[j])), float(p[j]), True, centroid_mm=stat,
                                       area_mm2=stat, source="head")
                timings[i]["head"] = head_s
        if now:
            t1 = time.perf_counter()
            made = self._reconstruct(checked[now])
            t2 = time.perf_counter()
            for i, rec in zip(now, made):
                recs[i] = rec
                t3 = time.perf_counter()
                out[i] = self._image_estimate(rec, flags[i], bool(contact[i]), stack[i],
                                              out[i], timings[i])
                timings[i].update(reconstruct=t2 - t1, pose=time.perf_counter() - t3)
        deferred = set(later)
        done = []
        for i, est in enumerate(out):
            timing = timings[i]
            timing["total"] = time.perf_counter() - t0
            if dated[i] is not None:
                timing["age"] = time.monotonic() - dated[i].t_host_s
            chips = int(flags[i].any(axis=-1).sum())
            if i in deferred:  # no flagged chip; building it anew keeps the image deferred (replace would read it)
                object.__setattr__(est, "timings_s", timing)
                done.append(est)
            else:
                done.append(replace(est, saturated_chips=chips, timings_s=timing))
        return done, (recs if images else None)

    def _judge(self, stack: np.ndarray, peaks: np.ndarray) -> tuple[np.ndarray, list[str]]:
        """Per reading of ``stack`` (n, R, C, 3): whether it holds a contact field (its largest |value| at least
        ``min_field_ut`` and, where the board has a press check, above its noise floor), and why it is no press
        ("" where it is one, or holds no contact)."""
        contact = peaks >= self.min_field_ut
        no_press = [""] * len(stack)
        if self.press_check is not None:  # a reading beyond the plausible bound is no answer already
            judged = np.flatnonzero(contact & (peaks < self._plausible_ut))
            for i, (touch, why) in zip(judged, self.press_check.judge_many(stack[judged])):
                contact[i], no_press[i] = touch, why
        return contact, no_press

    def set_noise_floor(self, noise_ut: np.ndarray) -> None:
        """Judge "no contact" against a measured noise floor (see
        :meth:`~tactile_manip.perception.contact.ContactEstimator.set_noise_floor`); no-op without a press check."""
        if self.press_check is not None:
            self.press_check = self.press_check.with_noise(noise_ut)

    def _reconstruct(self, checked: np.ndarray) -> list[Reconstruction]:
        """Reconstructions of checked readings (M, R, C, 3): one reading through the file's one-reading graph,
        several in one batched run."""
        if len(checked) == 1:
            return [self.reconstructor.reconstruct(checked[0])]
        return self.reconstructor.reconstruct_many(checked)

    def _image_estimate(self, rec: Reconstruction, flags: np.ndarray, contact: bool, field: np.ndarray,
                        given: AngleEstimate | None, timing: dict[str, float]) -> AngleEstimate:
        """The estimate of a reading whose image was decoded (``given``: an answer already made without it, kept),
        escalated when its confidence is low and the estimator has an escalation."""
        if given is not None:
            return given
        est = self._angle(rec, flags, contact, field)
        # the head reads the reading, not the image: another reconstruction of the same reading cannot change its
        # angle, so only an angle that came from the image escalates (on the head's route: where the head stood
        # aside, a chip flagged or an image without contact)
        if (self.escalation is not None and contact and est.confidence < self.escalate_below
                and est.source == "image" and est.plausible):
            t0 = time.perf_counter()
            est = replace(self._angle(self.escalation.reconstruct(field), flags, contact, field), escalated=True)
            timing["escalate"] = time.perf_counter() - t0
        return est

    def _angle(self, rec: Reconstruction, flags: np.ndarray, contact: bool,
               field: np.ndarray) -> AngleEstimate:
        """The angle and its confidence: the image's PCA, times the prior samples' agreement and the unsaturated
        fraction of chips (``flags`` (R, C, A)); with an angle head, the head's reading of ``field`` in its place
        or weighed against it (:meth:`_with_head`); calibrated last when the estimator has a calibration."""
        if not contact:
            return AngleEstimate(0.0, 0.0, False, reason=NO_CONTACT_FIELD)
        est = angle_from_image(rec.depth_mm, pixel_mm=self.reconstructor.pixel_mm, params=self.params)
        if est.defined:
            confidence = est.confidence
            if rec.spread_mm is not None:
                confidence *= _sample_agreement(rec, self.params.threshold_mm)
            if flags.any():
                confidence *= _unsaturated_fraction(flags)
            est = replace(est, confidence=confidence)
        # the head was trained on sound readings: a chip at its rail or beyond its range, or an image without any
        # contact, leaves the angle to the image (which clamps and sees where the contact is)
        if self.angle_head is not None and not flags.any() and est.reason != "empty contact":
            est = self._with_head(est, field)
        if est.defined and self.calibration is not None:
            est = replace(est, confidence=float(self.calibration(est.confidence)))
        if flags.any():  # after the calibration, which was fitted on readings without a railed chip
            est = replace(est, confidence=min(est.confidence, SATURATED_CONFIDENCE_CAP * _unsaturated_fraction(flags)))
        return est

    def _with_head(self, est: AngleEstimate, field: np.ndarray) -> AngleEstimate:
        """The angle head's estimate (route "head"), or the image's or the head's, whichever is the more likely
        within the tolerance (route "likelier").

        The head's probability comes from its von Mises concentration; the image's is its confidence, which only
        a calibration makes a probability (so "likelier" wants one).
        The head's estimate keeps the image's centroid and area, and is defined even where the image's is not
        (a short or faint contact whose reading still carries the axis).
        """
        angle, kappa = self.angle_head.axis(self.reconstructor.checked(field))
        p_head = within_probability(kappa, self._tolerance_rad)
        if self.angle_source == "likelier" and est.defined:
            p_image = est.confidence if self.calibration is None else float(self.calibration(est.confidence))
            if p_image >= p_head:
                return est
        return replace(est, angle_rad=float(wrap_axial(angle)), confidence=float(p_head), defined=True, reason="",
                       source="head")

    def estimate_frames(self, readings: Sequence[TactileReading | np.ndarray]) -> AngleEstimate:
        """Angle from the mean of several consecutive readings of one static contact (less chip noise)."""
        if len(readings) == 0:
            raise ValueError("estimate_frames needs at least one reading")
        fields = [np.asarray(_field(r)) for r in readings]
        shapes = {f.shape for f in fields}
        if len(shapes) != 1:
            raise ValueError(f"readings of different shapes cannot be averaged: {sorted(shapes)}")
        stacked = np.stack(fields).astype(np.float64)
        # a channel saturated (or out of range) in any frame is saturated in the mean
        flags = [r.saturated for r in readings if isinstance(r, TactileReading)] + list(out_of_range(stacked))
        t0 = time.perf_counter()
        # an implausible frame makes the mean implausible (NaN and inf were refused with the mean)
        why = self.implausible(stacked)
        return self._estimates([np.mean(stacked, axis=0)], [np.logical_or.reduce(flags)], [_dated(readings[-1])], t0,
                               why=[why])[0][0]


class _PendingImages:
    """The images of one call's estimates whose angle the head gave: decoded together, in one batched run, when
    the first of them is read (thread-safe), and measured as the image route measures them."""

    def __init__(self, estimator: TactilePoseEstimator, checked: np.ndarray) -> None:
        self._estimator, self._checked = estimator, checked
        self._stats: list[tuple[tuple[float, float], float]] | None = None
        self._lock = threading.Lock()

    def stats(self, index: int) -> tuple[tuple[float, float], float]:
        """(centroid (x, y) mm, area mm^2) of the ``index``-th image."""
        with self._lock:
            if self._stats is None:
                est = self._estimator
                self._stats = []
                for rec in est._reconstruct(self._checked):
                    image = angle_from_image(rec.depth_mm, pixel_mm=est.reconstructor.pixel_mm, params=est.params)
                    self._stats.append((image.centroid_mm, image.area_mm2))
                self._checked = None
        return self._stats[index]


class _PendingStat(Deferred):
    """The centroid or area of one pending image (:class:`_PendingImages`)."""

    __slots__ = ("images", "index")

    def __init__(self, images: _PendingImages, index: int) -> None:
        self.images, self.index = images, index

    def resolve(self, name: str) -> Any:
        centroid, area = self.images.stats(self.index)
        return centroid if name == "centroid_mm" else area


def _field(reading: TactileReading | np.ndarray) -> np.ndarray:
    """The field of a reading: a :class:`TactileReading`'s, or the array itself once it is known to hold real
    numbers (ValueError naming the dtype otherwise: a complex value would lose its imaginary part and True would
    read as 1 uT)."""
    if isinstance(reading, TactileReading):
        return reading.field_ut
    return real_field(reading)


def real_field(value: object) -> np.ndarray:
    """``value`` as an array of real numbers, unconverted (a float array is returned as it is: one attribute
    read); ValueError naming the dtype for complex, boolean, text or object values."""
    arr = value if isinstance(value, np.ndarray) else np.asarray(value)
    if arr.dtype.kind not in "fiu":
        raise ValueError(f"a reading holds real numbers (uT), got an array of dtype {arr.dtype}")
    return arr


def _saturated(reading: TactileReading | np.ndarray) -> np.ndarray | None:
    return reading.saturated if isinstance(reading, TactileReading) else None


def _dated(reading: TactileReading | np.ndarray) -> TactileReading | None:
    return reading if isinstance(reading, TactileReading) else None


def plausible_limits_ut(metadata: Mapping[str, Any], *, channels: int, board_layout: str,
                        magnetic_ut: bool = True) -> np.ndarray:
    """(channels,) uT: a reading with a |value| at or beyond its channel's limit is implausible for a model.

    The bound is the model's own where its metadata stores one (``input.plausible_field_ut``, uT), else its board
    layout's (:data:`PLAUSIBLE_FIELD_UT`), else none; for MLX90393 fields in uT (``magnetic_ut``) it never exceeds
    what the chip can report as a change (:data:`CHANGE_LIMIT_UT`, per axis x, y, z).

    Raises:
        ModelFileError: a stored bound that is not a positive number.
    """
    stored = metadata.get("input", {}).get("plausible_field_ut") if isinstance(metadata.get("input"), dict) else None
    if stored is None:
        bound = PLAUSIBLE_FIELD_UT.get(board_layout, math.inf) if magnetic_ut else math.inf
    elif isinstance(stored, (int, float)) and not isinstance(stored, bool) and stored > 0:
        bound = float(stored)
    else:
        raise ModelFileError(f"metadata field input.plausible_field_ut is {stored!r}, not a positive number of uT; "
                             "export the model again with `tactile-manip export`")
    if not magnetic_ut:
        return np.full(channels, bound)
    change = CHANGE_LIMIT_UT if channels == 3 else np.full(channels, CHANGE_LIMIT_UT.max())
    return np.minimum(change, bound)


def implausible_field(field_ut: np.ndarray, limits_ut: np.ndarray, *, magnetic_ut: bool = True) -> str:
    """Why the reading ``field_ut`` (..., R, C, A) is implausible: its first channel at or beyond its limit in
    ``limits_ut`` (A,) (from :func:`plausible_limits_ut`), or NaN, and how many more; "" when none is.
    ``magnetic_ut``: the reading holds MLX90393 fields in uT (whose change limit the sentence may name)."""
    f = np.asarray(field_ut, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(f) < limits_ut)  # NaN fails the comparison: implausible too
    count = int(np.count_nonzero(bad))
    if count == 0:
        return ""
    *_, row, col, axis = (int(i) for i in np.argwhere(bad)[0])
    value, limit = float(f[tuple(np.argwhere(bad)[0])]), float(limits_ut[axis])
    xyz = f.shape[-1] == 3
    if magnetic_ut and xyz and abs(value) >= CHANGE_LIMIT_UT[axis]:
        limit, what = float(CHANGE_LIMIT_UT[axis]), "more than a baseline-subtracted MLX90393 reading can hold"
    else:
        what = "far beyond the field of a press, which the model was not made for"
    more = f" (and {count - 1} more channel{'s' * (count > 2)})" if count > 1 else ""
    unit = " uT" if magnetic_ut else ""
    return (f"chip ({row}, {col}) reads {value:.4g}{unit} along {'xyz'[axis] if xyz else f'channel {axis}'}{more}, "
            f"at or beyond {limit:.5g}{unit}: {what}")


def _model_metadata(reconstructor: Reconstructor) -> Mapping[str, Any]:
    """The metadata of the model file behind ``reconstructor`` (through wrappers such as the symmetrized one),
    or {} for a reconstructor without one (the interpolation baselines)."""
    while reconstructor is not None:
        metadata = getattr(reconstructor, "metadata", None)
        if isinstance(metadata, Mapping):
            return metadata
        reconstructor = getattr(reconstructor, "inner", None)
    return {}


def _unsaturated_fraction(saturated: np.ndarray) -> float:
    """Fraction of chips (R, C) none of whose axes is at the rail, from (R, C, A) flags."""
    flags = np.asarray(saturated, dtype=bool)
    return 1.0 - float(flags.any(axis=-1).mean()) if flags.size else 1.0


def _sample_agreement(rec: Reconstruction, threshold_mm: float) -> float:
    """1 - mean(spread)/mean(depth) over the contact pixels, in [0, 1] (1: the prior samples agree)."""
    depth = np.asarray(rec.depth_mm, np.float64)
    contact = depth > threshold_mm
    if not contact.any():
        return 0.0
    spread = np.nan_to_num(np.asarray(rec.spread_mm, np.float64), nan=np.inf)
    ratio = float(spread[contact].mean() / depth[contact].mean())
    return float(np.clip(1.0 - ratio, 0.0, 1.0)) if np.isfinite(ratio) else 0.0
