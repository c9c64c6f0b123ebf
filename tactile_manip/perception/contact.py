"""The contact API: one magnetic reading in, where the contact is, how deep and how hard it presses, out.

:class:`ContactEstimator` runs an exported contact model (``tactile-manip export`` of a ``kind = "contact"``
run; onnxruntime, no torch) on a reading (R, C, 3) in microtesla, baseline-subtracted, and returns a
:class:`ContactState`: position x/y (mm), depth (mm), normal force (N), shear x/y (N) where the model was
trained on them (None otherwise), the in-contact flag, and a sigma (one standard deviation, same unit) for
each. It keeps the last few readings itself, for models that read a short temporal context::

    from tactile_manip.perception.contact import ContactEstimator
    contact = ContactEstimator("models/contact.onnx")
    state = contact.estimate(field_ut)            # (R, C, 3) uT -> ContactState
    if state.in_contact and state.force_n is not None:
        print(state.force_n, "+-", state.force_sigma_n)
    for state in contact.stream(sensor):         # one state per new frame, like TactilePoseEstimator.stream
        ...

With the pose estimator, one reading gives angle, location and force
(:class:`~tactile_manip.perception.contact_pose.TactileEstimator`).

The context: frame k of the model's input is the k-th reading before the newest one given to this estimator,
when it is at most the model's ``context["max_gap_s"]`` older (by ``TactileReading.t_host_s``, or the call's
``t_s``, or the time of the call); otherwise the newest reading takes its place, as in training. The model
learnt the context at its training stream's frame period (``context["frame_period_s"]``): feed it readings
at about that rate. :meth:`ContactEstimator.reset` forgets the history.

Bad input raises ValueError naming the problem (wrong shape, NaN or infinite values: nothing is estimated and
the history is unchanged); a missing or foreign model file raises
:class:`~tactile_manip.perception.reconstruct.ModelFileError` naming the path.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tactile_manip.extras import require
from tactile_manip.perception.contact_context import ContextBuffer
from tactile_manip.perception.estimator import StreamStats, stream_estimates
from tactile_manip.perception.onnx_session import session_options
from tactile_manip.perception.reconstruct import ModelFileError, read_metadata
from tactile_manip.types import TactileReading

if TYPE_CHECKING:
    from tactile_manip.sensors.base import TactileSensor

# ContactState field of each standard target, and of its sigma
STATE_FIELDS = {"x_mm": "x_sigma_mm", "y_mm": "y_sigma_mm", "depth_mm": "depth_sigma_mm",
                "force_n": "force_sigma_n", "shear_x_n": "shear_x_sigma_n", "shear_y_n": "shear_y_sigma_n"}
CONTACT_FLAG = "in_contact"


@dataclass(frozen=True)
class ContactState:
    """The contact in one reading. A quantity the model was not trained on is None, as is its sigma.

    Position and depth describe the contact: read them when ``in_contact`` is True. Forces are what the model
    gives (about 0 N without contact for a model trained on free readings too). Sigmas are one standard
    deviation of the model's Gaussian (ensemble mixture), in the quantity's unit. ``values`` and ``sigmas``
    hold every target of the model by name (also those beyond the standard ones, e.g. a stage's ``z_mm``).
    """

    in_contact: bool
    x_mm: float | None = None
    y_mm: float | None = None
    depth_mm: float | None = None
    force_n: float | None = None
    shear_x_n: float | None = None
    shear_y_n: float | None = None
    x_sigma_mm: float | None = None
    y_sigma_mm: float | None = None
    depth_sigma_mm: float | None = None
    force_sigma_n: float | None = None
    shear_x_sigma_n: float | None = None
    shear_y_sigma_n: float | None = None
    in_contact_probability: float | None = None  # the model's in_contact output clipped to [0, 1], where trained
    values: Mapping[str, float] = field(default_factory=dict)
    sigmas: Mapping[str, float] = field(default_factory=dict)
    context_frames: int = 1      # frames of real context used (1: the reading alone)
    latency_s: float = 0.0

    @property
    def position_mm(self) -> tuple[float, float] | None:
        """(x, y) in mm where the model gives both, else None."""
        return None if self.x_mm is None or self.y_mm is None else (self.x_mm, self.y_mm)


class ContactEstimator:
    """An exported contact model on onnxruntime (see the module docstring).

    Args:
        path: the ``.onnx`` file of ``tactile-manip export`` (a contact model).
        threads: onnxruntime intra-op threads (1: what a control loop wants).
        min_field_ut: for a model without an ``in_contact`` target, a reading whose largest |field| is below
            this is "not in contact" (the pose estimator's rule). A model with one uses its own output (> 0.5).
    """

    def __init__(self, path: str | Path, *, threads: int = 1, min_field_ut: float = 20.0) -> None:
        if not (np.isfinite(min_field_ut) and min_field_ut >= 0):
            raise ValueError(f"min_field_ut must be a finite value >= 0, got {min_field_ut!r}")
        self.path = Path(path)
        self.metadata = read_metadata(self.path)  # ModelFileError: missing, not ONNX, not ours
        if self.metadata.get("kind") != "contact":
            raise ModelFileError(f"{self.path}: not a contact model (kind {self.metadata.get('kind', 'image')!r}); "
                                 "export one from a `kind = \"contact\"` training run")
        try:
            shape = self.metadata["input"]["shape"]
            self.context_frames = int(shape[1])
            self.input_shape: tuple[int, int, int] = (int(shape[2]), int(shape[3]), int(shape[4]))
            self.target_names: tuple[str, ...] = tuple(self.metadata["targets"]["names"])
            self.units: tuple[str, ...] = tuple(self.metadata["targets"]["units"])
            context = self.metadata.get("context", {})
            self.max_gap_s = float(context.get("max_gap_s", 0.0))
        except (KeyError, IndexError, TypeError, ValueError) as e:
            raise ModelFileError(f"{self.path}: contact model metadata is incomplete ({type(e).__name__}: {e})") from e
        self.board_layout = str(self.metadata.get("board_layout", ""))
        self.min_field_ut = float(min_field_ut)
        ort = require("onnxruntime", "running a contact model")
        try:
            self.session = ort.InferenceSession(str(self.path), sess_options=session_options(ort, threads=threads),
                                                providers=["CPUExecutionProvider"])
        except Exception as e:  # noqa: BLE001 - onnxruntime raises its own Fail/InvalidGraph classes
            raise ModelFileError(f"{self.path}: onnxruntime cannot load it: {' '.join(str(e).split())[:200]}") from e
        self._history = ContextBuffer(self.context_frames, self.max_gap_s)
        self._state_fields = [(n, STATE_FIELDS[n]) for n in self.target_names if n in STATE_FIELDS]

    def __repr__(self) -> str:
        return (f"ContactEstimator({str(self.path)!r}, targets={list(self.target_names)}, "
                f"context_frames={self.context_frames}, board_layout={self.board_layout!r})")

    def reset(self) -> None:
        """Forget the readings kept for context (the next estimate reads its reading alone)."""
        self._history.clear()

    def check_layout(self, layout: str) -> None:
        """Refuse a sensor of another board layout than the model's."""
        if self.board_layout and layout != self.board_layout:
            raise ValueError(f"{self.path.name} takes readings of the {self.board_layout!r} board layout, but the "
                             f"sensor has the {layout!r} layout: train a contact model for that board")

    def estimate(self, reading: TactileReading | np.ndarray, *, t_s: float | None = None) -> ContactState:
        """The contact in ``reading`` (R, C, 3) uT, baseline-subtracted, with the readings before it as context.

        ``t_s``: the reading's time (s, monotonic); default its ``t_host_s``, or the time of the call.

        Raises:
            ValueError: wrong shape, or NaN / infinite values (nothing is estimated, the history is unchanged).
        """
        t0 = time.perf_counter()
        field_ut = self._check(reading)
        if t_s is None:
            t_s = reading.t_host_s if isinstance(reading, TactileReading) else time.monotonic()
        window = self._history.push(field_ut, float(t_s))
        mean, sigma = self.session.run(None, {"field_ut": window[None]})
        return self._state(mean[0], sigma[0], field_ut, self._history.frames_used, time.perf_counter() - t0)

    def stream(self, sensor: TactileSensor, *, timeout_s: float = 0.1, max_estimates: int | None = None,
               stats: StreamStats | None = None) -> Iterator[ContactState]:
        """Yield one state per new frame of ``sensor``, always from the newest frame (stale ones are skipped,
        as :meth:`TactilePoseEstimator.stream <tactile_manip.perception.TactilePoseEstimator.stream>` does).

        Raises SensorTimeoutError when the sensor stalls, ValueError when its board layout is not the model's.
        """
        self.check_layout(sensor.layout.name)
        return stream_estimates(sensor, self.estimate, timeout_s=timeout_s, max_estimates=max_estimates,
                                stats=stats)

    def _check(self, reading: TactileReading | np.ndarray) -> np.ndarray:
        field_ut = reading.field_ut if isinstance(reading, TactileReading) else reading
        arr = np.asarray(field_ut, dtype=np.float32)
        if arr.shape != self.input_shape:
            raise ValueError(f"expected a reading of shape {self.input_shape} (rows, cols, axes) for "
                             f"{self.path.name}, got {arr.shape}")
        if not np.isfinite(arr).all():
            bad = int((~np.isfinite(arr)).sum())
            raise ValueError(f"the reading holds {bad} NaN or infinite value(s): nothing estimated")
        return arr

    def _state(self, mean: np.ndarray, sigma: np.ndarray, field_ut: np.ndarray, used: int,
               latency_s: float) -> ContactState:
        values = dict(zip(self.target_names, mean.tolist()))
        sigmas = dict(zip(self.target_names, sigma.tolist()))
        kwargs: dict[str, Any] = {}
        for name, sigma_field in self._state_fields:
            kwargs[name], kwargs[sigma_field] = values[name], sigmas[name]
        if CONTACT_FLAG in values:
            probability = float(np.clip(values[CONTACT_FLAG], 0.0, 1.0))
            kwargs["in_contact_probability"] = probability
            in_contact = probability > 0.5
        else:
            in_contact = bool(np.max(np.abs(field_ut)) >= self.min_field_ut)
        return ContactState(in_contact=in_contact, values=values, sigmas=sigmas, context_frames=used,
                            latency_s=latency_s, **kwargs)

