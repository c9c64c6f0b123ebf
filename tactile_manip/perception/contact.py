"""The contact API: one magnetic reading in, where the contact is, how deep and how hard it presses, out.

:class:`ContactEstimator` runs an exported contact model (``tactile-manip export`` of a ``kind = "contact"``
run; onnxruntime, no torch) on a reading (R, C, 3) in microtesla, baseline-subtracted, and returns a
:class:`ContactState`: position x/y (mm), depth (mm), normal force (N), shear x/y (N) where the model was
trained on them (None otherwise), the in-contact flag, and a sigma (one standard deviation, same unit) for
each, calibrated on held-out samples where the model carries a map
(:class:`~tactile_manip.perception.confidence.SigmaCalibration`). It keeps the last few readings itself, for
models that read a short temporal context::

    from tactile_manip.perception.contact import ContactEstimator
    contact = ContactEstimator("contact")         # the shipped models/contact_supermag.onnx, or a path
    state = contact.estimate(field_ut)            # (R, C, 3) uT -> ContactState
    if state.in_contact and state.force_n is not None:
        print(state.force_n, "+-", state.force_sigma_n)

It reads no sensor: it is the contact part of the
:class:`~tactile_manip.perception.tactile_estimator.TactileEstimator` users take (``TactileEstimator.load()``:
the shipped pose and contact models), whose ``read`` and ``stream`` give angle, location and force of a
sensor's frames.

The context: frame k of the model's input is the k-th reading before the newest one given to this estimator,
when it is at most the model's ``context["max_gap_s"]`` older (by ``TactileReading.t_host_s``, or the call's
``t_s``, or the time of the call); otherwise the newest reading takes its place, as in training. The model
learnt the context at its training stream's frame period (``context["frame_period_s"]``): feed it readings
at about that rate. :meth:`ContactEstimator.reset` forgets the history.

Bad input raises ValueError naming the problem (wrong shape, NaN or infinite values: nothing is estimated and
the history is unchanged); a missing or foreign model file raises
:class:`~tactile_manip.perception.reconstruct.ModelFileError` naming the path.

No contact is no contact: on a board whose chip noise is known, a reading within the board's noise floor
(:class:`~tactile_manip.perception.press_check.PressCheck`: rated chip noise and a drift allowance, a stated
0.1 % false-alarm rate) gives ``in_contact`` False and no quantity; the model does not run on it.

No answer is silently wrong: a state is flagged (``plausible`` False, ``implausible_reason`` saying why) and holds
no quantity (every value and sigma None, ``values`` and ``sigmas`` empty) when

- the reading is above the noise floor with a pattern no simulated press of the board makes (the press check's
  likeness; the reason starts with "no press"): ``in_contact`` is True and the model does not run;

- the reading holds a |value| at or beyond :attr:`ContactEstimator.plausible_limits_ut` (more than an MLX90393
  can report as a change, or far beyond the field of a press: the model's ``input.plausible_field_ut``, else its
  board's :data:`~tactile_manip.perception.estimator.PLAUSIBLE_FIELD_UT`, 2000 uT on the SuperMag board, the
  pose estimator's bound). The model does not run, the reading stays out of the context, and ``in_contact`` is
  the field rule (largest |value| >= ``min_field_ut``);
- the model's output is non-finite, places the contact off the pad (:data:`CHECKED_TARGETS`: +-10 mm on the
  SuperMag board, the layout's grid times pitch; the trained range for a layout not known here) or gives a force
  outside its trained range (``targets.range`` where the file stores it, widened by
  :data:`TRAINED_RANGE_MARGIN`; else the training targets' mean +- :data:`TRAINED_RANGE_SIGMAS` standard
  deviations: -7.3 to 22.5 N for ``models/contact_supermag.onnx``). ``in_contact`` is then the model's.

On the 8675 simulated presses below 2000 uT checked (the shipped training and test sets' configs, rods and bars
at 2-15 N on drawn sensors) the shipped model's position stays within 8.7 mm and its force within 0.3-14.9 N:
no plausible press is flagged, and its state is the one the model gave before these checks.

Speed: a call is built for a control loop on one thread (``python -m benchmarks.bench_contact`` measures it).
The model's input and outputs are arrays allocated once and bound to the onnxruntime session, so a call copies
the reading into the context window, runs the graph and reads two small arrays back; nothing else is
allocated but the returned state. An estimator keeps its history and these arrays: give each thread its own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.boards.identity import check_board_of, check_model_of_current_board
from tactile_manip.extras import require
from tactile_manip.perception.confidence import SigmaCalibration
from tactile_manip.perception.contact_context import ContextBuffer
from tactile_manip.perception.estimator import implausible_field, plausible_limits_ut, real_field
from tactile_manip.perception.model_metadata import check_metadata
from tactile_manip.perception.onnx_session import session_options
from tactile_manip.perception.press_check import PressCheck, press_check_for
from tactile_manip.perception.reconstruct import ModelFileError, read_metadata, recipe_of
from tactile_manip.shipped import resolve_model_path
from tactile_manip.types import TactileReading

if TYPE_CHECKING:
    from tactile_manip.boards.board import Board

# ContactState field of each standard target, and of its sigma
STATE_FIELDS = {"x_mm": "x_sigma_mm", "y_mm": "y_sigma_mm", "depth_mm": "depth_sigma_mm",
                "force_n": "force_sigma_n", "shear_x_n": "shear_x_sigma_n", "shear_y_n": "shear_y_sigma_n"}
CONTACT_FLAG = "in_contact"
#: outputs checked against where a contact can be and what the model was trained on: the position against the
#: pad (the board layout's cells, grid times pitch: +-10 mm on the SuperMag board), the forces against their
#: trained range
CHECKED_TARGETS = ("x_mm", "y_mm", "force_n", "shear_x_n", "shear_y_n")
#: a target's trained range where the model stores none (``targets.range``): the training targets' mean +- this
#: many standard deviations (``normalisation.target_offset`` / ``target_scale``). A target drawn uniformly spans
#: +-1.73 of them, so 4 leaves 2.3 times its half-width: -7.3 to 22.5 N for the shipped model's 0-15 N presses
TRAINED_RANGE_SIGMAS = 4.0
#: a stored trained range [low, high] is widened by this share of its width on each side
TRAINED_RANGE_MARGIN = 0.25


@dataclass(frozen=True)
class ContactState:
    """The contact in one reading. A quantity the model was not trained on is None, as is its sigma.

    Position and depth describe the contact: read them when ``in_contact`` is True. Forces are what the model
    gives (about 0 N without contact for a model trained on free readings too). Sigmas are one standard
    deviation of the model's Gaussian (ensemble mixture), in the quantity's unit. ``values`` and ``sigmas``
    hold every target of the model by name (also those beyond the standard ones, e.g. a stage's ``z_mm``).

    ``plausible`` is False when the state is no answer (``implausible_reason`` says why): the reading holds a
    value beyond what the chip can report or far beyond the field of a press (the model is then not run on it,
    the reading does not enter the context, and ``in_contact`` is the field rule: its largest |value| >=
    ``min_field_ut``), or the model's output is non-finite, places the contact off the pad, or gives a force
    outside its trained range (``in_contact`` is then the model's, where finite). Every quantity and sigma is
    then None, and ``values`` and ``sigmas`` are empty: no number of an implausible state can be used by mistake.
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
    context_frames: int = 1      # frames of real context used (1: the reading alone; 0: the model did not run)
    latency_s: float = 0.0
    plausible: bool = True
    implausible_reason: str = ""  # "" when plausible

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
            Both only where the board has no press check (or ``press_check`` is False).
        press_check: judge each reading with the board's
            :class:`~tactile_manip.perception.press_check.PressCheck` first (the default, where the board's chip
            noise is known): within the noise floor "no contact", above it and unlike any press "no press" (no
            answer), and the model runs only on the rest. False runs the model on every reading.
    """

    def __init__(self, path: str | Path, *, threads: int = 1, min_field_ut: float = 20.0,
                 press_check: bool = True) -> None:
        if not (np.isfinite(min_field_ut) and min_field_ut >= 0):
            raise ValueError(f"min_field_ut must be a finite value >= 0, got {min_field_ut!r}")
        self.path = resolve_model_path(path)  # a shipped model's name, or a checkout's path from any folder
        self.metadata = read_metadata(self.path)  # ModelFileError: missing, not ONNX, not ours
        if self.metadata.get("kind") != "contact":
            raise ModelFileError(f"{self.path}: not a contact model (kind {self.metadata.get('kind', 'image')!r}); "
                                 "export one from a `kind = \"contact\"` training run")
        check_model_of_current_board(str(self.path), self.metadata, recipe_of(self.path))
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
        #: the no-contact and press-likeness tests of the board (None for a board whose chip noise is unknown here:
        #: the field rule and the model's in_contact output then decide)
        self.press_check: PressCheck | None = (press_check_for(self.board_layout, self.input_shape)
                                               if press_check else None)
        channels = self.metadata["input"].get("channels", {"kind": "magnetic_vector", "unit": "uT"})
        self._magnetic_ut = channels.get("kind") == "magnetic_vector" and channels.get("unit") == "uT"
        if not self._magnetic_ut:  # the board's chip noise is a floor of fields in uT only
            self.press_check = None
        #: (channels,) uT: a reading with a |value| at or beyond its channel's limit is implausible (no answer)
        self.plausible_limits_ut = plausible_limits_ut(self.metadata, channels=self.input_shape[-1],
                                                       board_layout=self.board_layout, magnetic_ut=self._magnetic_ut)
        self._plausible_ut = float(self.plausible_limits_ut.min())  # below it, one comparison says "plausible"
        try:
            #: (name, low, high, what) of each output a state is checked against (see CHECKED_TARGETS)
            self.output_bounds: tuple[tuple[str, float, float, str], ...] = self._output_bounds()
        except (AttributeError, TypeError, ValueError) as e:
            raise ModelFileError(f"{self.path}: its targets' range or normalisation is unreadable "
                                 f"({type(e).__name__}: {e})") from e
        self._bounds = [(self.target_names.index(n), n, lo, hi, what) for n, lo, hi, what in self.output_bounds]
        ort = require("onnxruntime", "running a contact model")
        try:
            self.session = ort.InferenceSession(str(self.path), sess_options=session_options(ort, threads=threads),
                                                providers=["CPUExecutionProvider"])
        except Exception as e:  # noqa: BLE001 - onnxruntime raises its own Fail/InvalidGraph classes
            raise ModelFileError(f"{self.path}: onnxruntime cannot load it: {' '.join(str(e).split())[:200]}") from e
        check_metadata(self.metadata, self.session, path=self.path)  # frames and targets against the graph
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

    def _output_bounds(self) -> tuple[tuple[str, float, float, str], ...]:
        """Where each of the model's :data:`CHECKED_TARGETS` can lie: the pad for the position (where the board
        layout is known), else the trained range (stored, or from the normalisation); unchecked without either."""
        pad = _pad_half_size_mm(self.board_layout)
        stored = self.metadata.get("targets", {}).get("range", {})
        norm = self.metadata.get("normalisation", {})
        offset, scale = norm.get("target_offset", []), norm.get("target_scale", [])
        bounds = []
        for k, name in enumerate(self.target_names):
            if name not in CHECKED_TARGETS:
                continue
            if pad is not None and name in ("x_mm", "y_mm"):
                half = pad[name == "y_mm"]
                bounds.append((name, -half, half, f"the {self.board_layout} pad"))
            elif isinstance(stored, dict) and name in stored:
                lo, hi = (float(v) for v in stored[name])
                margin = TRAINED_RANGE_MARGIN * (hi - lo)
                bounds.append((name, lo - margin, hi + margin, "the trained range"))
            elif len(offset) == len(scale) == len(self.target_names):
                lo, hi = offset[k] - TRAINED_RANGE_SIGMAS * scale[k], offset[k] + TRAINED_RANGE_SIGMAS * scale[k]
                bounds.append((name, float(lo), float(hi), "the trained range"))
        return tuple(bounds)

    def __repr__(self) -> str:
        return (f"ContactEstimator({str(self.path)!r}, targets={list(self.target_names)}, "
                f"context_frames={self.context_frames}, board_layout={self.board_layout!r})")

    def reset(self) -> None:
        """Forget the readings kept for context (the next estimate reads its reading alone)."""
        self._history.clear()

    def check_layout(self, layout: str | Board) -> None:
        """Refuse a sensor of another board layout (a name, or a sensor's Board) than the model's."""
        if check_board_of(self.path.name, self.metadata, layout):
            return
        layout = getattr(layout, "name", layout)
        if self.board_layout and layout != self.board_layout:
            raise ValueError(f"{self.path.name} takes readings of the {self.board_layout!r} board layout, but the "
                             f"sensor has the {layout!r} layout: train a contact model for that board")

    def estimate(self, reading: TactileReading | np.ndarray, *, t_s: float | None = None) -> ContactState:
        """The contact in ``reading`` (R, C, 3) uT, baseline-subtracted, with the readings before it as context.

        ``t_s``: the reading's time (s, monotonic); default its ``t_host_s``, or the time of the call.

        A reading beyond what the chip can report or far beyond the field of a press (:attr:`plausible_limits_ut`),
        and a state whose output is non-finite, off the pad or outside the trained range (:attr:`output_bounds`),
        give a state with ``plausible`` False and no quantities (see :class:`ContactState`).

        Raises:
            ValueError: wrong shape, or NaN / infinite values (nothing is estimated, the history is unchanged).
        """
        t0 = time.perf_counter()
        if isinstance(reading, TactileReading):
            field_ut, peak_ut, why = self._check(reading.field_ut)
            if t_s is None:
                t_s = reading.t_host_s
        else:
            field_ut, peak_ut, why = self._check(reading)
        if why:  # no answer, and the reading stays out of the context
            return self._implausible_state(peak_ut >= self.min_field_ut, None, why, time.perf_counter() - t0)
        self._history.push(field_ut, time.monotonic() if t_s is None else float(t_s))  # the bound input
        unmeasured = self._unmeasured(field_ut, t0)
        if unmeasured is not None:  # no contact, or no press: the frame is context, the model does not run
            return unmeasured
        self.session.run_with_iobinding(self._binding)                                # into _mean, _sigma
        return self._state(peak_ut, time.perf_counter() - t0)

    def estimate_many(self, readings: Sequence[TactileReading | np.ndarray]) -> list[ContactState]:
        """The contact in each of several pads' readings (each (R, C, 3) uT, baseline-subtracted), in one batched
        run of the model; each state equals what :meth:`estimate` gives for its reading alone (no context).

        Raises:
            ValueError: a model that reads frames before the newest (its context is one pad's history: use one
                estimator per pad), a wrong shape, or NaN / infinite values (nothing is estimated; the history
                is unchanged).
        """
        if self.context_frames != 1:
            raise ValueError(f"{self.path.name} reads {self.context_frames} frames of one pad's history; several "
                             "pads' readings need one ContactEstimator each")
        t0 = time.perf_counter()
        checked = [self._check(r.field_ut if isinstance(r, TactileReading) else r) for r in readings]
        sound = [f for f, _, why in checked if not why]
        if self.press_check is not None and sound:  # every reading judged in one batched product
            self.press_check.judge_many(np.stack(sound))
        unmeasured = [None if why else self._unmeasured(f, t0) for f, _, why in checked]
        run = [i for i, (_, _, why) in enumerate(checked) if not why and unmeasured[i] is None]
        mean = sigma = np.empty((0, len(self.target_names)), np.float32)
        if run:
            batch = np.stack([checked[i][0] for i in run])[:, None].astype(np.float32, copy=False)
            mean, sigma = self.session.run(None, {"field_ut": batch})
        latency = time.perf_counter() - t0
        states: list[ContactState] = []
        rows = {i: k for k, i in enumerate(run)}
        for i, (_, peak_ut, why) in enumerate(checked):
            if why:
                states.append(self._implausible_state(peak_ut >= self.min_field_ut, None, why, latency, frames=0))
            elif unmeasured[i] is not None:
                states.append(replace(unmeasured[i], latency_s=latency))
            else:
                states.append(self._state_of(mean[rows[i]].tolist(), sigma[rows[i]].tolist(), peak_ut, latency, 1))
        return states

    def set_noise_floor(self, noise_ut: np.ndarray) -> None:
        """Judge "no contact" against a measured noise floor: ``noise_ut`` (3,) per axis or (R, C, 3) per channel
        (a sensor's ``baseline.noise_ut``), uT, with the drift allowance, never below the board's rated floor
        (:meth:`~tactile_manip.perception.press_check.PressCheck.with_noise`). No-op for a board without a
        :class:`~tactile_manip.perception.press_check.PressCheck`."""
        if self.press_check is not None:
            self.press_check = self.press_check.with_noise(noise_ut)

    def _unmeasured(self, field_ut: np.ndarray, t0: float) -> ContactState | None:
        """The state of a reading the model is not run on: within the noise floor (no contact: ``in_contact``
        False, plausible, no quantities), or above it with a pattern no press makes (``plausible`` False); None
        for a press to measure, or where the board has no press check."""
        if self.press_check is None:
            return None
        contact, no_press = self.press_check.judge(field_ut)
        if contact and not no_press:
            return None
        if not contact:
            return ContactState(in_contact=False, context_frames=0, latency_s=time.perf_counter() - t0)
        return self._implausible_state(True, None, no_press, time.perf_counter() - t0, frames=0)

    def _check(self, field_ut: np.ndarray) -> tuple[np.ndarray, float, str]:
        """The reading as float32 (R, C, A), its largest |value| (uT) and why it is implausible ("" when it is
        not); ValueError for a wrong shape or a NaN or infinite value. One reduction decides for a plausible
        reading: NaN and inf carry through the maximum, and a peak below every limit is plausible."""
        field_ut = real_field(field_ut)  # ValueError for complex, boolean or text values
        if field_ut.dtype == np.float32:
            arr = field_ut
        else:
            with np.errstate(over="ignore"):  # a float64 beyond float32's range is judged below, not warned about
                arr = np.asarray(field_ut, dtype=np.float32)
        if arr.shape != self.input_shape:
            raise ValueError(f"expected a reading of shape {self.input_shape} (rows, cols, axes) for "
                             f"{self.path.name}, got {arr.shape}")
        peak_ut = float(np.abs(arr, out=self._abs).max())
        if peak_ut < self._plausible_ut:
            return arr, peak_ut, ""
        if not math.isfinite(peak_ut):
            given = np.asarray(field_ut, dtype=np.float64)
            bad = int(given.size - np.count_nonzero(np.isfinite(given)))
            if bad:
                raise ValueError(f"the reading holds {bad} NaN or infinite value(s): nothing estimated")
            arr = given  # finite, beyond float32's range: a huge reading, not a broken one
        return arr, peak_ut, implausible_field(arr, self.plausible_limits_ut, magnetic_ut=self._magnetic_ut)

    def _state(self, peak_ut: float, latency_s: float) -> ContactState:
        """The state of the outputs the last run left in ``_mean`` and ``_sigma``."""
        return self._state_of(self._mean[0].tolist(), self._sigma[0].tolist(), peak_ut, latency_s,
                              self._history.frames_used)

    def _state_of(self, mean: list[float], sigma: list[float], peak_ut: float, latency_s: float,
                  frames_used: int) -> ContactState:
        """The state of one reading's outputs (one value and sigma per target), ``frames_used`` of context."""
        why = self._implausible_output(mean, sigma)
        if why:
            probability = None if self._flag is None else mean[self._flag]
            if probability is None or not math.isfinite(probability):  # the field rule, as without that output
                return self._implausible_state(peak_ut >= self.min_field_ut, None, why, latency_s)
            probability = min(max(probability, 0.0), 1.0)
            contact = True if self.press_check is not None else probability > 0.5  # the check saw a press
            return self._implausible_state(contact, probability, why, latency_s, frames=frames_used)
        for k, sigma_map in self.sigma_maps.items():
            sigma[k] = sigma_map.one(sigma[k])
        fields = self._blank.copy()
        for k, name, sigma_field in self._state_fields:
            fields[name], fields[sigma_field] = mean[k], sigma[k]
        if self._flag is not None:
            probability = min(max(mean[self._flag], 0.0), 1.0)
            fields["in_contact_probability"] = probability
            fields["in_contact"] = True if self.press_check is not None else probability > 0.5
        elif self.press_check is not None:
            fields["in_contact"] = True  # the press check found a press above the noise floor
        else:
            fields["in_contact"] = peak_ut >= self.min_field_ut
        fields["values"] = dict(zip(self.target_names, mean))
        fields["sigmas"] = dict(zip(self.target_names, sigma))
        fields["context_frames"] = frames_used
        fields["latency_s"] = latency_s
        # the frozen dataclass's __init__ sets each of its 18 fields through object.__setattr__, which costs as
        # much as the rest of this method; the instance is the same (test_contact_estimator.py compares them)
        state = object.__new__(ContactState)
        state.__dict__.update(fields)
        return state

    def _implausible_output(self, mean: list[float], sigma: list[float]) -> str:
        """Why the model's outputs (one value and sigma per target) are no answer, "" when they are one."""
        if not math.isfinite(sum(mean) + sum(sigma)):  # NaN and inf carry through the sum
            return "the model gave a non-finite output"
        for k, name, lo, hi, what in self._bounds:
            if not lo <= mean[k] <= hi:
                return f"{name} {mean[k]:.4g} is outside {what} ({lo:.4g} to {hi:.4g})"
        return ""

    def _implausible_state(self, in_contact: bool, probability: float | None, why: str,
                           latency_s: float, *, frames: int | None = None) -> ContactState:
        """A state that is no answer (every quantity None), with its in-contact flag and why; ``frames``: the
        context the model read (default: the history's, where the model ran; 0 where it did not)."""
        if frames is None:
            frames = self._history.frames_used if probability is not None else 0
        return ContactState(in_contact=bool(in_contact), in_contact_probability=probability, values={}, sigmas={},
                            context_frames=frames if probability is not None else 0,
                            latency_s=latency_s, plausible=False, implausible_reason=why)


def _pad_half_size_mm(layout: str) -> tuple[float, float] | None:
    """Half the pad's size (x, y) in mm: the board layout's cells (grid times pitch), or None for a layout
    that is not known here."""
    if not layout:
        return None
    from tactile_manip.boards import load_board

    try:
        board = load_board(layout)
    except (ValueError, OSError):  # a board of its own (a dataset's layout name): no geometry
        return None
    rows, cols = board.grid
    return cols * board.pitch_mm / 2.0, rows * board.pitch_mm / 2.0
