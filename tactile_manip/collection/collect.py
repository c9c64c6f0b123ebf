"""The synchronized pair recorder: MBTS frames (125 Hz) and VBTS depth frames (~30 Hz), triggered on force.

As in SuperMag's symmetric rig (Sec. III-D), one object is squeezed between the two pads by a gripper that
closes to a force threshold (10 N). :class:`PairCollector`:

1. prepares: the MBTS baseline and the VBTS reference, both only while the force source reads no press
   (below ``release_n``), the reference also checked against the calibration's for a hidden contact;
2. streams: every MBTS frame from a subscription, stamped with its host time (mapped from the device clock
   by :class:`~tactile_manip.collection.sync.DeviceClock`, so USB bursts do not smear it); every camera frame
   with its capture time (minus the camera's latency);
3. triggers: when the force at a camera frame's time first reaches ``threshold_n``, the next
   ``pairs_per_press`` camera frames at or above the threshold are taken; the trigger re-arms when the
   force falls below ``release_n`` (the gripper opened);
4. pairs each taken frame with the MBTS frame nearest in time, only within ``tolerance_s``
   (:class:`~tactile_manip.collection.sync.StreamPairer`); a frame without one is logged as unpaired and the
   press may take the next frame instead;
5. writes each pair (depth from the calibrated pipeline, quantised as the dataset stores it) to the
   append-only, fsynced pair log (:mod:`~tactile_manip.collection.pair_log`).

The force comes from a :class:`~tactile_manip.collection.force.ForceSource`: the gripper (wrap its reading in
``FunctionForce``), the MBTS itself as a proxy (``FieldForce``) or, in simulation, the press script
(``ScriptForce``).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from tactile_manip.checks import check_finite_scalar
from tactile_manip.errors import CalibrationError, SensorTimeoutError
from tactile_manip.sensors.base import TactileSensor
from tactile_manip.collection.camera import Camera, CameraFrame
from tactile_manip.collection.force import ForceSource, PressTrigger
from tactile_manip.collection.pair_log import PairLogWriter, PairRecord
from tactile_manip.collection.sync import DeviceClock, Match, StreamPairer
from tactile_manip.collection.vbts_calibration import VbtsCalibration, check_reference_clear
from tactile_manip.data import quantise_depth


@dataclass(frozen=True)
class CollectConfig:
    """How pairs are triggered, synchronized and written (times in s, forces in N)."""

    threshold_n: float = 10.0          # trigger: the gripper's press force threshold (SuperMag: 10 N)
    release_n: float = 2.0             # re-arm (and allow reference/baseline) below this force, N
    pairs_per_press: int = 1           # camera frames taken per press once the threshold is reached
    settle_s: float = 0.0              # wait this long after the threshold before taking frames, s
    tolerance_s: float = 0.005         # a pair's frames are at most this far apart in time, s
    camera_latency_s: float = 0.0      # exposure-to-timestamp delay of the camera, subtracted, s
    mbts_clock: Literal["device", "host"] = "device"  # MBTS frame time: device clock mapped to host, or arrival
    reference_frames: int = 15         # no-contact camera frames averaged into the reference
    baseline_frames: int = 125         # no-contact MBTS frames averaged into the baseline (1 s)
    camera_timeout_s: float = 1.0      # the camera is declared stopped after this long without a frame, s
    mbts_timeout_s: float = 0.5        # the MBTS is declared stopped after this long without a frame, s
    sync_every_s: float = 0.5          # fsync the pair log at least this often, s
    object_name: str = "object"        # label of the pairs when the force source gives none

    def __post_init__(self) -> None:
        for name in ("threshold_n", "tolerance_s", "camera_timeout_s", "mbts_timeout_s", "sync_every_s"):
            check_finite_scalar(f"CollectConfig.{name}", getattr(self, name), low=0.0, low_open=True)
        for name in ("release_n", "settle_s", "camera_latency_s"):
            check_finite_scalar(f"CollectConfig.{name}", getattr(self, name), low=0.0)
        if self.release_n >= self.threshold_n:
            raise ValueError(f"CollectConfig.release_n ({self.release_n}) must be below threshold_n "
                             f"({self.threshold_n})")
        for name in ("pairs_per_press", "reference_frames", "baseline_frames"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < (2 if name != "pairs_per_press" else 1):
                raise ValueError(f"CollectConfig.{name} must be an integer >= {2 if name != 'pairs_per_press' else 1}, "
                                 f"got {v!r}")
        if self.mbts_clock not in ("device", "host"):
            raise ValueError(f"CollectConfig.mbts_clock must be 'device' or 'host', got {self.mbts_clock!r}")
        if not self.object_name:
            raise ValueError("CollectConfig.object_name must not be empty")


@dataclass
class CollectSummary:
    """What a :meth:`PairCollector.run` did."""

    path: Path
    presses: int = 0              # presses that reached the threshold
    complete_presses: int = 0     # presses that got all their pairs
    pairs: int = 0
    unpaired: int = 0             # taken camera frames without an MBTS frame within the tolerance
    max_abs_dt_s: float = 0.0     # largest |t_field - t_depth| among the pairs, s
    mean_abs_dt_s: float = 0.0
    camera_frames: int = 0
    camera_dropped: int = 0
    mbts_frames: int = 0
    seconds: float = 0.0


class PairCollector:
    """Records synchronized (MBTS reading, VBTS depth) pairs to a pair log (see the module docstring).

    The sensor and the camera are handed in connected; the collector does not own them.
    """

    def __init__(self, sensor: TactileSensor, camera: Camera, calibration: VbtsCalibration, force: ForceSource,
                 path: str | Path, *, config: CollectConfig | None = None,
                 header: dict[str, Any] | None = None) -> None:
        self.sensor, self.camera, self.force = sensor, camera, force
        self.calibration = calibration
        self.pipeline = calibration.pipeline()
        self.config = config or CollectConfig()
        self.path = Path(path)
        self.header = header or {}
        self._clock = DeviceClock()
        self._dts: list[float] = []
        self._last_field_arrival = time.monotonic()
        self.summary = CollectSummary(self.path)
        self._prepared = False

    # ------------------------------------------------------------------ preparation

    def prepare(self) -> None:
        """Take the MBTS baseline and the VBTS reference with the pad free.

        Raises:
            CalibrationError: the force source reads a press, the reference looks pressed, or the baseline
                is refused (noise: something touched the pad).
            CameraTimeoutError, SensorTimeoutError: a device stopped.
        """
        self._require_no_press("take the baseline and the reference")
        self.sensor.calibrate_baseline(self.config.baseline_frames)
        self.camera.drain()
        frames = [self._read_camera() for _ in range(self.config.reference_frames)]
        self._require_no_press("take the reference", frames)
        reference = self.pipeline.set_reference([f.image for f in frames])
        check_reference_clear(reference, self.calibration.reference, pixel_mm=self.calibration.alignment.raw_pixel_mm)
        self._prepared = True

    def _require_no_press(self, what: str, frames: Sequence[CameraFrame] = ()) -> None:
        times = [f.t_host_s - self.config.camera_latency_s for f in frames] or [time.monotonic()]
        worst = max(self.force.force_n(t) for t in times)
        if worst >= self.config.release_n:
            raise CalibrationError(f"the gripper presses with {worst:.1f} N (>= release_n {self.config.release_n} N): "
                                   f"open it to {what} with the pads free")

    # ------------------------------------------------------------------ recording

    def run(self, *, presses: int | None = None, duration_s: float | None = None,
            stop: threading.Event | None = None, progress: Callable[[CollectSummary], None] | None = None
            ) -> CollectSummary:
        """Record until ``presses`` presses are complete, ``duration_s`` passed, ``stop`` is set or the force
        source finishes. Returns the summary; the log is complete up to any exception raised.

        Raises:
            CameraTimeoutError: the camera stopped (no frame for ``camera_timeout_s``).
            SensorTimeoutError: the MBTS stopped (no frame for ``mbts_timeout_s`` while frames wait for it).
        """
        if not self._prepared:
            raise CalibrationError("no MBTS baseline and VBTS reference for this session: call prepare() first")
        cfg = self.config
        stop = stop or threading.Event()
        trigger = PressTrigger(cfg.threshold_n, cfg.release_n, cfg.pairs_per_press, cfg.settle_s)
        pairer = StreamPairer(cfg.tolerance_s)
        summary = self.summary = CollectSummary(self.path)
        self._dts = []
        t0 = time.monotonic()
        header = {**self.header, "config": dataclasses.asdict(cfg), "pixel_mm": self.calibration.alignment.out_pixel_mm,
                  "mbts": self.sensor.source, "camera": self.camera.source, "calibration": self.calibration.report}
        self._last_field_arrival = t0
        with self.sensor.subscribe(max_frames=1 << 14) as sub, \
                PairLogWriter(self.path, header, sync_every_s=cfg.sync_every_s) as log:
            log.write_event(t0, {"event": "start", "reference_noise_levels": self.pipeline.reference.noise_levels})
            try:
                while not self._done(stop, trigger, presses, duration_s, t0):
                    frame = self._read_camera()
                    summary.camera_frames += 1
                    summary.mbts_frames += self._take_fields(sub, pairer)
                    t = frame.t_host_s - cfg.camera_latency_s
                    force = self.force.force_n(t)
                    before = trigger.presses
                    press = trigger.want(t, force)
                    if trigger.presses > before:
                        log.write_event(t, {"event": "trigger", "press": trigger.presses - 1, "force_n": force})
                    if press is not None:
                        pairer.add_depth(t, (frame, force, press, self.force.label(t)))
                    self._settle(pairer, summary, log, trigger)
                    if progress:
                        progress(self._fill(summary, trigger, t0))
            except BaseException as e:
                log.write_event(time.monotonic(), {"event": "error", "error": f"{type(e).__name__}: {e}"})
                raise
            finally:
                try:  # frames already taken still get their pairs (or are logged unpaired)
                    self._finish(pairer, sub, summary, log, trigger)
                except Exception as e:  # noqa: BLE001 - never hide the error that ended the run
                    log.write_event(time.monotonic(), {"event": "error", "error": f"finishing: {e}"})
                final = dataclasses.asdict(self._fill(summary, trigger, t0))
                log.write_event(time.monotonic(), {"event": "stop", **final})
        return summary

    def _done(self, stop: threading.Event, trigger: PressTrigger, presses: int | None, duration_s: float | None,
              t0: float) -> bool:
        now = time.monotonic()
        return (stop.is_set() or (presses is not None and trigger.complete >= presses)
                or (duration_s is not None and now - t0 >= duration_s) or self.force.finished(now))

    def _read_camera(self) -> CameraFrame:
        return self.camera.read(self.config.camera_timeout_s)

    def _take_fields(self, sub: Any, pairer: StreamPairer) -> int:
        items = sub.drain()
        for item in items:
            r = item.reading
            t = self._clock.update(r.t_host_s, r.t_device_s) if self.config.mbts_clock == "device" else r.t_host_s
            pairer.add_field(t, r)
        if items:
            self._last_field_arrival = time.monotonic()
        return len(items)

    def _settle(self, pairer: StreamPairer, summary: CollectSummary, log: PairLogWriter, trigger: PressTrigger
                ) -> None:
        if pairer.pending and time.monotonic() - self._last_field_arrival > self.config.mbts_timeout_s:
            raise SensorTimeoutError(f"no MBTS frame for {self.config.mbts_timeout_s:.2f} s from {self.sensor.source} "
                                     "while camera frames wait for their pair: is the board still streaming? "
                                     "(`tactile-manip view` shows it live)")
        for match in pairer.resolve():
            self._write(match, summary, log, trigger)

    def _finish(self, pairer: StreamPairer, sub: Any, summary: CollectSummary, log: PairLogWriter,
                trigger: PressTrigger) -> None:
        """Give pending frames the MBTS frames that belong to them, then decide the rest."""
        deadline = time.monotonic() + self.config.tolerance_s + 0.1
        while pairer.pending and time.monotonic() < deadline:
            summary.mbts_frames += self._take_fields(sub, pairer)
            for match in pairer.resolve():
                self._write(match, summary, log, trigger)
            time.sleep(0.005)
        for match in pairer.resolve(flush=True):
            self._write(match, summary, log, trigger)

    def _write(self, match: Match, summary: CollectSummary, log: PairLogWriter, trigger: PressTrigger) -> None:
        frame, force, press, label = match.depth
        trigger.result(press, match.paired)
        if not match.paired:
            summary.unpaired += 1
            log.write_event(match.t_depth_s, {"event": "unpaired", "seq_depth": frame.seq, "press": press,
                                              "reason": f"no MBTS frame within {self.config.tolerance_s * 1e3:.1f} ms"})
            return
        reading = match.field
        depth = self.pipeline.depth(frame.image)
        info = {"t_depth_s": match.t_depth_s, "t_field_s": match.t_field_s, "dt_s": match.dt_s,
                "seq_depth": frame.seq, "seq_field": reading.seq, "t_device_field_s": reading.t_device_s,
                "t_exposure_s": frame.t_exposure_s, "force_n": force, "press": press,
                "object": label.object_name if label else self.config.object_name,
                "pose": list(label.pose) if label and label.pose else None,
                "contact": bool(depth.max() > 0.05)}
        log.write_pair(match.t_depth_s, PairRecord(reading.field_ut, reading.field_raw_ut, reading.saturated,
                                                   quantise_depth(depth), info))
        summary.pairs += 1
        self._dts.append(abs(match.dt_s))

    def _fill(self, summary: CollectSummary, trigger: PressTrigger, t0: float) -> CollectSummary:
        summary.presses, summary.complete_presses = trigger.presses, trigger.complete
        if self._dts:
            summary.max_abs_dt_s, summary.mean_abs_dt_s = max(self._dts), float(np.mean(self._dts))
        summary.camera_dropped = self.camera.health().dropped
        summary.seconds = time.monotonic() - t0
        return summary
