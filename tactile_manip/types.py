"""Core value types shared by the layers (numpy only)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True, eq=False)
class TactileReading:
    """One magnetic tactile frame, as every sensor backend returns it.

    Attributes:
        field_ut: (R, C, 3) float32, baseline-subtracted field in microtesla, axes (x, y, z) of the pad frame,
            row 0 at +y, column 0 at -x (docs/design.md). Equal to ``field_raw_ut`` until a baseline is set.
        field_raw_ut: (R, C, 3) float32, field as the chips report it, microtesla.
        saturated: (R, C, 3) bool, channels at the ADC rail (their value is a bound, not a measurement).
        t_host_s: host monotonic time (``time.monotonic()``) when the frame became available, s.
        t_device_s: device timestamp (MCU clock), s; NaN where the backend has none.
        seq: frame sequence number (wraps at 2**16 on the wire; backends unwrap it).
        temperature_c: (R, C) chip temperatures in Celsius, or None when not sent.
    """

    field_ut: np.ndarray
    field_raw_ut: np.ndarray
    saturated: np.ndarray
    t_host_s: float
    t_device_s: float = float("nan")
    seq: int = 0
    temperature_c: np.ndarray | None = field(default=None)

    @property
    def shape(self) -> tuple[int, ...]:
        """Taxel grid and axes, e.g. (4, 4, 3)."""
        return tuple(self.field_ut.shape)


#: the ``reason`` of an angle estimate whose reading is implausible (its ``implausible_reason`` says why)
IMPLAUSIBLE_READING = "implausible reading"


class Deferred:
    """A value measured only when first read (an image that was not decoded yet): subclasses give the value of
    the field ``name`` from :meth:`resolve`."""

    def resolve(self, name: str) -> Any:
        raise NotImplementedError


class DeferredField:
    """A dataclass field whose value may be a :class:`Deferred`, resolved (once) on first read.

    The value lives in the instance's ``__dict__`` under ``_<name>``; assignment goes through :meth:`__set__`
    (a frozen dataclass's ``__init__`` too), so the field stays frozen for its users.
    """

    def __init__(self, default: Any) -> None:
        self.default = default

    def __set_name__(self, owner: type, name: str) -> None:
        self.name, self.slot = name, "_" + name

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:
            return self.default  # the dataclass reads the default through the class
        value = obj.__dict__[self.slot]
        if isinstance(value, Deferred):  # measure it now, keep the value
            value = value.resolve(self.name)
            obj.__dict__[self.slot] = value
        return value

    def __set__(self, obj: Any, value: Any) -> None:
        obj.__dict__[self.slot] = value


@dataclass(frozen=True)
class AngleEstimate:
    """In-plane orientation of a contact, as the pose pipeline reports it (an expected outcome, not an error).

    Attributes:
        angle_rad: principal axis, counter-clockwise from the pad +x axis, axial, in (-pi/2, pi/2];
            0.0 when ``defined`` is False.
        confidence: in [0, 1]: 1 - (minor / major eigenvalue) of the contact's second moments, times the
            agreement of prior samples where those are available; 0.0 when ``defined`` is False.
        defined: False for an empty, too small or isotropic contact, or an implausible reading (then ``reason`` says
            which).
        centroid_mm: contact centroid (x, y) in the pad frame, mm, measured on the reconstructed image. Where the
            angle came from the angle head, the image is decoded only when this (or ``area_mm2``) is first read,
            in one batch with every other such estimate of the same call.
        area_mm2: contact area, mm^2 (measured on the image as ``centroid_mm`` is).
        reason: why the angle is undefined ("" when defined).
        saturated_chips: chips with an axis at the ADC rail or beyond the chip's range (clamped before the
            reconstruction); with any, the confidence is at most
            :data:`~tactile_manip.perception.estimator.SATURATED_CONFIDENCE_CAP` times the fraction of chips
            without (after the calibration: a railed chip's value is a bound, not a measurement).
        timings_s: named durations of the estimate's stages in s (e.g. "reconstruct", "pose", "total"; and
            "age", from the reading's arrival to the estimate; "escalate" when extra inference ran), empty when
            not measured.
        escalated: the first pass was below the estimator's ``escalate_below`` and this estimate comes from its
            ``escalation`` reconstructor (extra inference: prior samples, symmetry averaging).
        source: where the angle comes from: "prior" (a method without tactile input, which answers the pad's x
            axis: :mod:`tactile_manip.perception.baselines`), "image" (the principal axis of the reconstructed image) or
            "head" (the model's angle head, read straight from the reading, where it was the more likely).
        plausible: False when the reading holds a value beyond what the chip can report as a change, or far
            beyond the field of a press the model was made for (2000 uT on the SuperMag board: see
            :mod:`tactile_manip.perception.estimator`); the estimate is then no answer: ``defined`` False,
            ``angle_rad`` and ``confidence`` 0.0, ``reason`` :data:`IMPLAUSIBLE_READING`.
        implausible_reason: what made the reading implausible (which chip, which value, which bound); "" when
            ``plausible``.
    """

    angle_rad: float
    confidence: float
    defined: bool
    centroid_mm: tuple[float, float] = DeferredField((0.0, 0.0))
    area_mm2: float = DeferredField(0.0)
    reason: str = ""
    saturated_chips: int = 0
    timings_s: dict[str, float] = field(default_factory=dict, compare=False)
    escalated: bool = False
    source: str = "image"
    plausible: bool = True
    implausible_reason: str = ""

    def __getstate__(self) -> dict[str, Any]:
        """The fields with every deferred one measured (a pickled or copied estimate holds values only)."""
        state = dict(self.__dict__)
        for name in ("centroid_mm", "area_mm2"):
            state["_" + name] = getattr(self, name)
        return state
