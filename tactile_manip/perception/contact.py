"""The contact API: one magnetic reading in, where the contact is, how deep and how hard it presses, out.

:class:`ContactEstimator` runs an exported contact model (``tactile-manip export`` of a ``kind = "contact"``
run; onnxruntime, no torch) on a reading (R, C, 3) in microtesla, baseline-subtracted, and returns a
:class:`ContactState`: position x/y (mm), depth (mm), normal force (N), shear x/y (N) where the model was
trained on them (None otherwise), the in-contact flag, and a sigma (one standard deviation, same unit) for
each, calibrated on held-out samples where the model carries a map
(:class:`~tactile_manip.perception.confidence.SigmaCalibration`). It keeps the last few readings itself, for
models that read a short temporal context::

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

Speed: a call is built for a control loop on one thread (``python -m benchmarks.bench_contact`` measures it).
The model's input and outputs are arrays allocated once and bound to the onnxruntime session, so a call copies
the reading into the context window, runs the graph and reads two small arrays back; nothing else is
allocated but the returned state. An estimator keeps its history and these arrays: give each thread its own.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tactile_manip.extras import require
from tactile_manip.perception.confidence import SigmaCalibration
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
        try:
            maps = {str(n): SigmaCalibration.from_dict(d)
                    for n, d in self.metadata.get("sigma_calibration", {}).items()}
        except (KeyError, TypeError, ValueError) as e:
            raise ModelFileError(f"{self.path}: its sigma calibration is unreadable ({type(e).__name__}: {e})") from e
        unknown = set(maps) - set(self.target_names)
        if unknown:
            raise ModelFileError(f"{self.path}: a sigma calibration for {sorted(unknown)}, which are not its targets")
        #: per target index, the map of the graph's sigma onto the calibrated one (models exported with one)
        self.sigma_maps: dict[int, SigmaCalibration] = {self.target_names.index(n): m for n, m in maps.items()}
        self.board_layout = str(self.metadata.get("board_layout", ""))
        #: the image centroid's share in a TactileEstimator's position (0: this model's position alone)
        weight = self.metadata.get("image_position_weight", 0.0)
        if not (isinstance(weight, (int, float)) and 0.0 <= weight <= 1.0):
            raise ModelFileError(f"{self.path}: its image_position_weight {weight!r} is not a share in [0, 1]")
        self.image_position_weight = float(weight)
        self.min_field_ut = float(min_field_ut)
        ort = require("onnxruntime", "running a contact model")
        try:
            self.session = ort.InferenceSession(str(self.path), sess_options=session_options(ort, threads=threads),
                                                providers=["CPUExecutionProvider"])
        except Exception as e:  # noqa: BLE001 - onnxruntime raises its own Fail/InvalidGraph classes
            raise ModelFileError(f"{self.path}: onnxruntime cannot load it: {' '.join(str(e).split())[:200]}") from e
        self._history = ContextBuffer(self.context_frames, self.max_gap_s, shape=self.input_shape)
        self._abs = np.empty(self.input_shape, np.float32)  # |reading|, allocated once
        self._state_fields = [(k, n, STATE_FIELDS[n]) for k, n in enumerate(self.target_names) if n in STATE_FIELDS]
        self._flag = self.target_names.index(CONTACT_FLAG) if CONTACT_FLAG in self.target_names else None
        self._blank = dict(vars(ContactState(in_contact=False)))  # every field of a state at its default
        self._binding, self._mean, self._sigma = self._bind(ort)

    def _bind(self, ort: Any) -> tuple[Any, np.ndarray, np.ndarray]:
        """Bind the context window and two preallocated (1, K) output arrays to the session, and run it once
        (the first run allocates onnxruntime's buffers; a model whose inputs or outputs are not those of
        ``tactile-manip export`` is refused here)."""
        inputs = [(i.name, i.type) for i in self.session.get_inputs()]
        outputs = [(o.name, o.type) for o in self.session.get_outputs()]
        expected = [("mean", "tensor(float)"), ("sigma", "tensor(float)")]
        if inputs != [("field_ut", "tensor(float)")] or outputs != expected:
            raise ModelFileError(f"{self.path}: a contact model takes float32 'field_ut' and gives float32 'mean' "
                                 f"and 'sigma'; this graph takes {inputs} and gives {outputs}")
        mean = np.zeros((1, len(self.target_names)), np.float32)
        sigma = np.zeros_like(mean)
        binding = self.session.io_binding()
        binding.bind_ortvalue_input("field_ut", ort.OrtValue.ortvalue_from_numpy(self._history.window[None]))
        binding.bind_ortvalue_output("mean", ort.OrtValue.ortvalue_from_numpy(mean))
        binding.bind_ortvalue_output("sigma", ort.OrtValue.ortvalue_from_numpy(sigma))
        try:
            self.session.run_with_iobinding(binding)
        except Exception as e:  # noqa: BLE001 - onnxruntime raises its own classes
            raise ModelFileError(f"{self.path}: the model does not run on one ({self.context_frames}, "
                                 f"{', '.join(map(str, self.input_shape))}) window with {len(self.target_names)} "
                                 f"targets: {' '.join(str(e).split())[:200]}") from e
        return binding, mean, sigma

    def calibrated_sigma(self, sigma: np.ndarray) -> np.ndarray:
        """The graph's sigmas (n, K) through the model's sigma calibration (a copy; unchanged without one)."""
        out = np.array(sigma, dtype=np.float64)
        for k, sigma_map in self.sigma_maps.items():
            out[:, k] = sigma_map(out[:, k])
        return out

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
        if isinstance(reading, TactileReading):
            field_ut, peak_ut = self._check(reading.field_ut)
            if t_s is None:
                t_s = reading.t_host_s
        else:
            field_ut, peak_ut = self._check(reading)
        self._history.push(field_ut, time.monotonic() if t_s is None else float(t_s))  # the bound input
        self.session.run_with_iobinding(self._binding)                                # into _mean, _sigma
        return self._state(peak_ut, time.perf_counter() - t0)

    def stream(self, sensor: TactileSensor, *, timeout_s: float = 0.1, max_estimates: int | None = None,
               stats: StreamStats | None = None) -> Iterator[ContactState]:
        """Yield one state per new frame of ``sensor``, always from the newest frame (stale ones are skipped,
        as :meth:`TactilePoseEstimator.stream <tactile_manip.perception.TactilePoseEstimator.stream>` does).

        Raises SensorTimeoutError when the sensor stalls, ValueError when its board layout is not the model's.
        """
        self.check_layout(sensor.layout.name)
        return stream_estimates(sensor, self.estimate, timeout_s=timeout_s, max_estimates=max_estimates,
                                stats=stats)

    def _check(self, field_ut: np.ndarray) -> tuple[np.ndarray, float]:
        """The reading as float32 (R, C, A) and its largest |value| (uT); ValueError for a wrong shape or a NaN
        or infinite value (one reduction finds both: NaN and inf carry through the maximum)."""
        arr = np.asarray(field_ut, dtype=np.float32)
        if arr.shape != self.input_shape:
            raise ValueError(f"expected a reading of shape {self.input_shape} (rows, cols, axes) for "
                             f"{self.path.name}, got {arr.shape}")
        peak_ut = float(np.abs(arr, out=self._abs).max())
        if not math.isfinite(peak_ut):
            bad = int(arr.size - np.count_nonzero(np.isfinite(arr)))
            raise ValueError(f"the reading holds {bad} NaN or infinite value(s): nothing estimated")
        return arr, peak_ut

    def _state(self, peak_ut: float, latency_s: float) -> ContactState:
        """The state of the outputs the last run left in ``_mean`` and ``_sigma``."""
        mean, sigma = self._mean[0].tolist(), self._sigma[0].tolist()
        for k, sigma_map in self.sigma_maps.items():
            sigma[k] = sigma_map.one(sigma[k])
        fields = self._blank.copy()
        for k, name, sigma_field in self._state_fields:
            fields[name], fields[sigma_field] = mean[k], sigma[k]
        if self._flag is not None:
            probability = min(max(mean[self._flag], 0.0), 1.0)
            fields["in_contact_probability"] = probability
            fields["in_contact"] = probability > 0.5
        else:
            fields["in_contact"] = peak_ut >= self.min_field_ut
        fields["values"] = dict(zip(self.target_names, mean))
        fields["sigmas"] = dict(zip(self.target_names, sigma))
        fields["context_frames"] = self._history.frames_used
        fields["latency_s"] = latency_s
        # the frozen dataclass's __init__ sets each of its 18 fields through object.__setattr__, which costs as
        # much as the rest of this method; the instance is the same (test_contact_estimator.py compares them)
        state = object.__new__(ContactState)
        state.__dict__.update(fields)
        return state

