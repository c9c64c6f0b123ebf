"""Recording a live sensor: :class:`Recorder` writes every frame of a connected sensor, plus health snapshots,
to a recording file.

The file format, its writer and its reader (``RecordingWriter``, ``Recording``, ``read_recording``, ``MAGIC``,
``FORMAT_VERSION``, the record layout and tags) live in :mod:`tactile_manip.logs.recording`, below the sensors
layer, and are named here too.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tactile_manip.errors import RecordingError, SensorTimeoutError
from tactile_manip.logs.framed_file import TAG_EVENT
from tactile_manip.logs.recording import (
    FORMAT_VERSION,
    MAGIC,
    RECORD,
    TAG_FRAME,
    TAG_HEALTH,
    Recording,
    RecordingWriter,
    read_recording,
)
from tactile_manip.wire.protocol import TEMPERATURE_LSB_C, CountScale, encode_frame

if TYPE_CHECKING:
    from tactile_manip.sensors.base import SensorFrame, SensorHealth, TactileSensor

__all__ = ["FORMAT_VERSION", "MAGIC", "RECORD", "TAG_EVENT", "TAG_FRAME", "TAG_HEALTH", "RecordSummary", "Recorder",
           "Recording", "RecordingWriter", "read_recording", "recording_header"]


def recording_header(sensor: TactileSensor, **extra: Any) -> dict[str, Any]:
    """Header fields describing ``sensor``: source, backend, chip settings, wire format and board layout."""
    chip = sensor.chip
    return {"source": sensor.source, "backend": type(sensor).__name__, "wire_format": sensor.wire_format,
            "layout": sensor.layout.name,
            "chip": {"lsb_xy_ut": chip.lsb_xy_ut, "lsb_z_ut": chip.lsb_z_ut,
                     "saturation_counts": chip.saturation_counts, "noise_xy_ut": chip.noise_xy_ut,
                     "noise_z_ut": chip.noise_z_ut, "rate_hz": chip.rate_hz},
            "host_clock": "time.monotonic() of the recording host, s", **extra}


@dataclass
class RecordSummary:
    """What a :meth:`Recorder.run` wrote."""

    frames: int                # frame records written
    seconds: float             # wall time recorded, s
    subscriber_overflows: int  # frames lost because the writer fell more than 16384 frames behind


class Recorder:
    """Write every frame of a connected sensor to a recording, plus a health record every ``health_every_s``.

    Frames are taken from a subscription (never from the ring buffer), so none is skipped; backends without
    wire bytes (simulated, replay) are encoded into wire frames from their raw counts.
    """

    def __init__(self, sensor: TactileSensor, path: str | Path, *, sync_every_s: float = 0.5,
                 health_every_s: float = 1.0, metadata: dict[str, Any] | None = None) -> None:
        self.sensor = sensor
        self.path = Path(path)
        self.sync_every_s = sync_every_s
        self.health_every_s = health_every_s
        self.metadata = metadata or {}
        self._scale = CountScale.from_chip(sensor.chip)

    def run(self, *, duration_s: float | None = None, stop: threading.Event | None = None,
            on_health: Callable[[SensorHealth], None] | None = None) -> RecordSummary:
        """Record until ``duration_s`` elapsed or ``stop`` is set (or KeyboardInterrupt); returns a summary."""
        stop = stop or threading.Event()
        t0 = time.monotonic()
        next_health = t0 + self.health_every_s
        with self.sensor.subscribe(max_frames=1 << 14) as sub, \
                RecordingWriter(self.path, recording_header(self.sensor, **self.metadata),
                                sync_every_s=self.sync_every_s) as out:
            try:
                while not stop.is_set() and (duration_s is None or time.monotonic() - t0 < duration_s):
                    try:
                        self._write(out, sub.get(0.1))
                    except SensorTimeoutError:
                        pass  # a stalled sensor: keep recording, the health records show it
                    for item in sub.drain():
                        self._write(out, item)
                    now = time.monotonic()
                    if now >= next_health:
                        next_health = now + self.health_every_s
                        self._health(out, now, on_health)
                    out.maybe_sync()
            finally:
                for item in sub.drain():
                    self._write(out, item)
                self._health(out, time.monotonic(), None)
            return RecordSummary(frames=out.frames, seconds=time.monotonic() - t0,
                                 subscriber_overflows=sub.overflowed)

    def _write(self, out: RecordingWriter, item: SensorFrame) -> None:
        wire = item.wire
        if wire is None:
            r = item.reading
            if r.field_raw_ut.shape != (4, 4, 3):
                raise RecordingError(f"{self.sensor.source} gives {r.field_raw_ut.shape} readings without wire "
                                     "bytes; only SuperMag (4, 4, 3) readings can be re-encoded into a recording")
            temps = None if r.temperature_c is None else np.rint(r.temperature_c / TEMPERATURE_LSB_C).astype(np.int16)
            t_us = int(round(r.t_device_s * 1e6)) if math.isfinite(r.t_device_s) else 0
            wire = encode_frame(self._scale.to_counts(r.field_raw_ut), seq=r.seq, t_mcu_us=t_us, status=item.status,
                                temperature_raw=temps)
        out.write_frame(item.reading.t_host_s, wire)

    def _health(self, out: RecordingWriter, now: float, on_health: Callable[[SensorHealth], None] | None) -> None:
        h = self.sensor.health()
        out.write_health(now, dataclasses.asdict(h))
        if on_health is not None:
            on_health(h)
