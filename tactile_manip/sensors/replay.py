"""The replay backend: a recording served through the sensor interface.

Two paces: ``"recorded"`` plays frames on a thread at their recorded host timing (times ``speed``), so a
consumer sees what it would have seen live; ``"on_demand"`` serves the next recorded frame on every
``read_latest``/``wait_new`` call, as fast as the consumer asks, which makes offline evaluation deterministic.
Served readings carry the serving time as ``t_host_s`` (staleness works as live) and the recorded device
time and counter (offset on every loop so ``seq`` keeps increasing).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from typing import Any

import numpy as np

from tactile_manip.chips import MLX90393, ChipModelSpec
from tactile_manip.errors import RecordingError, SensorTimeoutError
from tactile_manip.sensors.base import TactileSensor
from tactile_manip.sensors.config import ReplaySensorConfig
from tactile_manip.boards import load_board
from tactile_manip.logs.recording import Recording, read_recording
from tactile_manip.types import TactileReading


class ReplaySensor(TactileSensor):
    """A recorded sensor (see :class:`~tactile_manip.sensors.base.TactileSensor` for the contract).

    The file is read on ``connect()``; the chip LSBs and rated noise come from its header.
    """

    def __init__(self, config: ReplaySensorConfig) -> None:
        super().__init__(source=config.path, chip=MLX90393, buffer_frames=config.buffer_frames,
                         baseline=config.baseline)
        self.config = config
        self.recording: Recording | None = None
        self._next = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._cpu_s = 0.0
        self._last_error = ""

    @property
    def finished(self) -> bool:
        """Every frame was served and ``loop`` is off."""
        rec = self.recording
        return rec is not None and not self.config.loop and self._next >= len(rec)

    # ------------------------------------------------------------------ TactileSensor hooks

    def _open(self) -> None:
        rec = read_recording(self.config.path)
        if len(rec) == 0:
            raise RecordingError(f"{self.config.path} holds no frame to replay")
        chip = rec.header.get("chip", {})
        known = {f.name for f in dataclasses.fields(ChipModelSpec)}
        self._chip = dataclasses.replace(MLX90393, **{k: v for k, v in chip.items() if k in known})
        try:
            self._layout = load_board(rec.layout_name)
        except ValueError as e:
            raise RecordingError(f"{self.config.path}: {e}") from None
        self.recording, self._next = rec, 0
        self._field_ut, self._saturated = rec.field_raw_ut(), rec.saturated()
        self._seq_span = int(rec.seq[-1] - rec.seq[0]) + 1
        self._period_s = float(np.median(np.diff(rec.t_host_s))) if len(rec) > 1 else 1.0 / self._chip.rate_hz
        self._start_session()
        if self.config.pace == "recorded":
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, daemon=True, name="tactile-replay")
            self._thread.start()
            with self._cond:
                self._cond.wait_for(lambda: self._frames > 0, timeout=2.0)

    def _close(self) -> None:
        self._stop_producer()

    def _link_health(self) -> dict[str, Any]:
        rec = self.recording  # damage skipped in the file shows as the wire's CRC errors and resync bytes
        return {"link_up": self._connected and not self.finished, "reader_cpu_s": self._cpu_s,
                "last_error": self._last_error, "crc_errors": rec.damaged_records if rec else 0,
                "resync_bytes": rec.skipped_bytes if rec else 0}

    def _stale_hint(self) -> str:
        if self.finished:
            return (f"the replay reached the end of the recording ({len(self.recording)} frames); "
                    "pass loop=True to start over")
        return "the replay thread is not keeping up (is the machine overloaded?)"

    # ------------------------------------------------------------------ on-demand pace

    def read_latest(self, max_age_s: float = 0.1) -> TactileReading:
        if self.config.pace == "on_demand":
            self._serve_on_demand()
        return super().read_latest(max_age_s)

    def wait_new(self, timeout_s: float = 0.1) -> TactileReading:
        if self.config.pace == "on_demand":
            self._serve_on_demand()
        return super().wait_new(timeout_s)

    def _collect(self, n: int, timeout_s: float) -> list[TactileReading]:
        if self.config.pace != "on_demand":
            return super()._collect(n, timeout_s)
        return [self._serve_on_demand() for _ in range(n)]

    def _serve_on_demand(self) -> TactileReading:
        self._require_connected()
        if self.finished:
            raise SensorTimeoutError(self._stale_message("no frame left"))
        return self._serve()

    # ------------------------------------------------------------------ serving

    def _serve(self) -> TactileReading:
        rec, i = self.recording, self._next
        loop, j = divmod(i, len(rec))
        self._next = i + 1
        temps = None if rec.temperature_c is None else rec.temperature_c[j].copy()
        loop_s = rec.t_device_s[-1] - rec.t_device_s[0] + self._period_s
        return self._publish(self._field_ut[j].copy(), self._saturated[j].copy(),
                             seq=int(rec.seq[j]) + loop * self._seq_span, t_host_s=time.monotonic(),
                             t_device_s=float(rec.t_device_s[j]) + loop * loop_s, status=int(rec.status[j]),
                             temperature_c=temps)

    def _run(self) -> None:
        cpu0 = time.thread_time()
        rec, speed = self.recording, self.config.speed
        t_rec = rec.t_host_s - rec.t_host_s[0]
        loop_s = t_rec[-1] + self._period_s
        t0 = time.monotonic()
        while not self._stop.is_set() and not self.finished:
            loop, j = divmod(self._next, len(rec))
            wait = t0 + (t_rec[j] + loop * loop_s) / speed - time.monotonic()
            if wait > 0 and self._stop.wait(wait):
                break
            try:
                self._serve()
            except Exception as e:  # noqa: BLE001 - the thread must survive anything and report it
                self._last_error = f"{type(e).__name__} in the replay thread: {e}"
            self._cpu_s = time.thread_time() - cpu0
