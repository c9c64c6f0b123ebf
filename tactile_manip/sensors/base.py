"""The ``TactileSensor`` interface: what every magnetic tactile sensor backend promises (docs/design.md, Wire protocol).

A backend produces frames on its own thread and hands each one to :meth:`TactileSensor._publish`; this
class keeps the ring buffer of recent readings, the "unseen frame" bookkeeping behind :meth:`wait_new`,
staleness checks, the baseline and the generic health counters, so all backends behave the same way.
"""

from __future__ import annotations

import abc
import collections
import dataclasses
import math
import queue
import threading
import time
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from tactile_manip.checks import check_array
from tactile_manip.chips import ChipSettings
from tactile_manip.errors import SensorDisconnectedError, SensorError, SensorTimeoutError
from tactile_manip.sensors.baseline import Baseline, baseline_from_frames, noise_thresholds_ut
from tactile_manip.sensors.config import BaselineConfig, DriftConfig
from tactile_manip.sensors.drift import BaselineState
from tactile_manip.boards import DEFAULT_BOARD, Board, load_board
from tactile_manip.types import TactileReading

RATE_WINDOW_S = 1.0  # the measured rate is taken over the last second of frames


@dataclass(frozen=True)
class SensorHealth:
    """A snapshot of a sensor's counters since its last ``connect()``.

    Byte-level counters (CRC, version, resync, reconnects) stay 0 for backends that move no bytes.
    """

    source: str                       # port path, "simulated", or the recording path
    connected: bool                   # between connect() and disconnect()
    link_up: bool                     # the data path is open right now (False while reconnecting)
    frames: int                       # frames delivered to the ring buffer
    seq_gaps: int                     # discontinuities of the frame counter within one open session
    frames_missed: int                # frames lost inside those gaps
    seq_resets: int                   # counter repeats or jumps backwards (device restarted)
    crc_errors: int = 0               # candidate frames rejected by the CRC
    version_errors: int = 0           # syncs followed by an unknown protocol version
    frame_errors: int = 0             # candidate frames refused by a length/value check (formats without CRC)
    resync_bytes: int = 0             # bytes skipped to find the next good frame
    dropped_at_start: int = 0         # frames discarded right after each (re)open
    reconnects: int = 0               # successful reopens after an error
    rate_hz: float = math.nan         # frames per second over the last second
    last_frame_age_s: float = math.inf  # time since the newest frame arrived, s
    reader_cpu_s: float = 0.0         # CPU time of the backend's producer thread, s
    reader_cpu_fraction: float = 0.0  # that CPU time over the time connected (1.0 = one core)
    last_error: str = ""              # the last error the producer thread caught, or ""
    last_status: int = 0              # device status bits of the newest frame
    uptime_s: float = 0.0             # time since connect(), s
    baseline_tracking: bool = False   # the baseline is following a quiet pad right now (DriftConfig.track)
    baseline_updates: int = 0         # frames the tracked baseline moved on since it was set
    baseline_moved_ut: float = 0.0    # largest change of the tracked offset since it was set, uT
    common_mode_ut: tuple[float, float, float] = (math.nan, math.nan, math.nan)  # median field over chips, x y z, uT
    stray_field: bool = False         # all chips shifted together beyond DriftConfig.common_mode_ut (magnet, steel)


class SensorFrame(NamedTuple):
    """A reading with what the wire carried besides it (``wire`` is None for backends without bytes)."""

    reading: TactileReading
    status: int
    wire: bytes | None


class FrameSubscription:
    """Every frame a sensor publishes from now on, in order, until closed (for recorders and calibration).

    Frames are queued on the producer thread and never block it: past ``max_frames`` unread frames, new
    ones are dropped and counted in ``overflowed``.
    """

    def __init__(self, sensor: TactileSensor, max_frames: int) -> None:
        self._sensor = sensor
        self._queue: queue.Queue[SensorFrame] = queue.Queue(max_frames)
        self.overflowed = 0

    def get(self, timeout_s: float) -> SensorFrame:
        """The next frame; raises SensorTimeoutError after ``timeout_s`` without one."""
        try:
            return self._queue.get(timeout=max(timeout_s, 0.0))
        except queue.Empty:
            raise SensorTimeoutError(self._sensor._stale_message(f"no frame for {timeout_s:.2f} s")) from None

    def drain(self) -> list[SensorFrame]:
        """Every frame queued now, without waiting."""
        out = []
        while True:
            try:
                out.append(self._queue.get_nowait())
            except queue.Empty:
                return out

    def close(self) -> None:
        self._sensor._unsubscribe(self)

    def __enter__(self) -> FrameSubscription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _put(self, frame: SensorFrame) -> None:
        try:
            self._queue.put_nowait(frame)
        except queue.Full:
            self.overflowed += 1


class TactileSensor(abc.ABC):
    """A magnetic tactile sensor delivering :class:`~tactile_manip.types.TactileReading` frames.

    Readings have the shape of the sensor's board layout (:attr:`layout`): (4, 4, 3) for the SuperMag board.

    Contract, the same for every backend:

    - The constructor does no I/O. :meth:`connect` opens the source and returns once frames flow; on failure
      it releases what it opened and re-raises. :meth:`disconnect` is idempotent. The sensor is a context
      manager (connect on enter, disconnect on exit).
    - Readings are produced on a background thread at the sensor rate into a ring buffer of the last
      ``buffer_frames`` frames; ``seq`` is unwrapped and strictly increasing while connected.
    - :meth:`read_latest` returns the newest reading or raises :class:`SensorTimeoutError` when it is older
      than ``max_age_s``; :meth:`wait_new` blocks for a reading not yet returned by either method.
    - Until a baseline is set, ``field_ut`` equals ``field_raw_ut``; afterwards it is ``raw - offset``.
    - Calling a reading method while not connected raises :class:`SensorDisconnectedError`.
    - The producer thread never lets an exception escape: it records it in :meth:`health` and carries on
      (a serial backend reconnects).
    """

    def __init__(self, *, source: str, chip: ChipSettings, buffer_frames: int, baseline: BaselineConfig,
                 layout: Board | None = None, drift: DriftConfig | None = None) -> None:
        self._source = source
        self._chip = chip
        self._layout = layout = layout or load_board(DEFAULT_BOARD)
        self._state = BaselineState(drift or DriftConfig(), layout)
        self._baseline_config = baseline
        self._cond = threading.Condition()
        self._ring: collections.deque[TactileReading] = collections.deque(maxlen=buffer_frames)
        self._subs: tuple[FrameSubscription, ...] = ()
        self._connected = False
        self._baseline: Baseline | None = None
        self._rezero_frames = baseline.frames
        self._reset_counters()

    # ------------------------------------------------------------------ backend hooks

    @abc.abstractmethod
    def _open(self) -> None:
        """Open the source and start the producer; return once the first frame was published, or raise."""

    @abc.abstractmethod
    def _close(self) -> None:
        """Stop the producer and release everything; must not raise, may be called after a failed open."""

    def _stop_producer(self, timeout_s: float = 2.0) -> None:
        """Signal the backend's producer thread (``self._stop``, ``self._thread``) to end, and join it."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=timeout_s)
            self._thread = None

    def _link_health(self) -> dict[str, Any]:
        """Backend counters for :class:`SensorHealth` (byte-level fields, reader CPU, last error)."""
        return {"link_up": self._connected}

    def _stale_hint(self) -> str:
        """What to check when frames stop (appended to timeout messages)."""
        return "is the source still producing frames?"

    # ------------------------------------------------------------------ lifecycle

    @property
    def source(self) -> str:
        """Port path, "simulated", or the recording path."""
        return self._source

    @property
    def chip(self) -> ChipSettings:
        """Chip settings (LSBs, rail, rated noise) used to convert and to judge baselines."""
        return self._chip

    @property
    def layout(self) -> Board:
        """Where the board's chips sit and which reading cells they feed (readings are ``layout.shape``)."""
        return self._layout

    @property
    def wire_format(self) -> str:
        """The format of the wire bytes this sensor publishes (frames without bytes are recorded as "supermag")."""
        return "supermag"

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        """Open the source and wait for the first frame.

        Raises:
            SensorError: already connected.
            SensorDisconnectedError: the port could not be opened (the message says what to check).
            SensorTimeoutError: it opened but produced no valid frame in time.
            RecordingError: (replay) the recording is missing, unreadable or empty.
        """
        if self._connected:
            raise SensorError(f"{self._source} is already connected; call disconnect() first")
        with self._cond:
            self._ring.clear()
            self._reset_counters()
        self._connected = True
        try:
            self._open()
        except BaseException:
            self._connected = False
            self._close()
            raise

    def disconnect(self) -> None:
        """Stop reading and release the source; a no-op when not connected. Waiters get SensorDisconnectedError."""
        if not self._connected:
            return
        self._connected = False
        try:
            self._close()
        finally:
            with self._cond:
                self._cond.notify_all()

    def __enter__(self) -> TactileSensor:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()

    def __repr__(self) -> str:
        state = "connected" if self._connected else "disconnected"
        return f"{type(self).__name__}({self._source!r}, {state})"

    # ------------------------------------------------------------------ readings

    def read_latest(self, max_age_s: float = 0.1) -> TactileReading:
        """The newest reading, marked as seen.

        Raises:
            SensorTimeoutError: no frame yet, or the newest is older than ``max_age_s`` seconds.
            SensorDisconnectedError: not connected.
        """
        self._require_connected()
        with self._cond:
            latest = self._ring[-1] if self._ring else None
            if latest is not None:
                age = time.monotonic() - latest.t_host_s
                if age <= max_age_s:
                    self._seen_seq = max(self._seen_seq, latest.seq)
                    return latest
        what = "no frame yet" if latest is None else f"no frame for {age:.2f} s (limit {max_age_s:.2f} s)"
        raise SensorTimeoutError(self._stale_message(what))

    def wait_new(self, timeout_s: float = 0.1) -> TactileReading:
        """Block until a reading newer than any returned so far is available, and return the newest one.

        Returns at once when such a reading is already buffered. Frames in between are skipped here (see
        :meth:`window` or :meth:`subscribe` for every frame).

        Raises:
            SensorTimeoutError: none within ``timeout_s`` seconds.
            SensorDisconnectedError: not connected, or disconnected while waiting.
        """
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                self._require_connected()
                if self._ring and self._ring[-1].seq > self._seen_seq:
                    latest = self._ring[-1]
                    self._seen_seq = latest.seq
                    return latest
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                self._cond.wait(remaining)
        raise SensorTimeoutError(self._stale_message(f"no new frame within {timeout_s:.2f} s"))

    def window(self, n: int) -> list[TactileReading]:
        """The last ``n`` readings (fewer right after connecting), oldest first; does not mark them seen."""
        if not isinstance(n, int) or not 1 <= n <= self._ring.maxlen:
            raise ValueError(f"n must be an integer in [1, {self._ring.maxlen}] (buffer_frames), got {n!r}")
        self._require_connected()
        with self._cond:
            k = min(n, len(self._ring))
            return [self._ring[i] for i in range(len(self._ring) - k, len(self._ring))]

    def subscribe(self, max_frames: int = 4096) -> FrameSubscription:
        """Receive every frame from now on (with wire bytes where the backend has them) until closed."""
        sub = FrameSubscription(self, max_frames)
        with self._cond:
            self._subs = self._subs + (sub,)
        return sub

    # ------------------------------------------------------------------ baseline

    @property
    def baseline(self) -> Baseline | None:
        """The baseline in use, or None (then ``field_ut == field_raw_ut``)."""
        return self._baseline

    def calibrate_baseline(self, frames: int | None = None, *, timeout_s: float | None = None) -> Baseline:
        """Average the next ``frames`` frames (default ``BaselineConfig.frames``) into the baseline.

        Every reading returned afterwards (buffered ones included) reports ``raw - offset``. The pad must be
        free of contact.

        Raises:
            CalibrationError: a channel's noise exceeds the threshold (contact, or a faulty chip) or saturated.
            SensorTimeoutError: the frames did not arrive within ``timeout_s`` (default ``BaselineConfig``).
            SensorDisconnectedError: not connected.
        """
        n = self._baseline_config.frames if frames is None else int(frames)
        if n < 2:
            raise ValueError(f"frames must be >= 2, got {frames!r}")
        timeout = timeout_s if timeout_s is not None else max(self._baseline_config.timeout_s,
                                                              2.0 * n / self._chip.rate_hz)
        self._require_connected()
        got = self._collect(n, timeout)
        raw = np.stack([r.field_raw_ut for r in got])
        saturated = np.stack([r.saturated for r in got])
        thresholds = noise_thresholds_ut(self._baseline_config, self._chip)
        baseline = baseline_from_frames(raw, saturated, thresholds, source=self._source)
        if all(r.temperature_c is not None for r in got):  # the reference of temperature compensation
            baseline = dataclasses.replace(baseline, temperature_c=np.mean([r.temperature_c for r in got], axis=0))
        self._rezero_frames = n
        return self._use_baseline(baseline)

    def rezero(self, *, timeout_s: float | None = None) -> Baseline:
        """Take the baseline again with the same number of frames as the last one (pad free of contact)."""
        return self.calibrate_baseline(self._rezero_frames, timeout_s=timeout_s)

    def set_baseline(self, offset_ut: object) -> Baseline:
        """Use a known offset in uT of the reading's shape (``layout.shape``, (4, 4, 3) for SuperMag)."""
        offset = check_array("offset_ut", offset_ut, shape=self._layout.shape).astype(np.float32)
        return self._use_baseline(Baseline(offset_ut=offset, noise_ut=np.zeros_like(offset), frames=0,
                                           t_host_s=time.monotonic()))

    def clear_baseline(self) -> None:
        """Report raw fields again (``field_ut == field_raw_ut``)."""
        self._use_baseline(None)

    # ------------------------------------------------------------------ health

    def health(self) -> SensorHealth:
        """Counters since the last connect(), the measured rate and the newest frame's age."""
        now = time.monotonic()
        with self._cond:
            times = [r.t_host_s for r in self._tail_within(RATE_WINDOW_S)]
            base = dict(frames=self._frames, seq_gaps=self._gaps, frames_missed=self._missed,
                        seq_resets=self._resets, last_status=self._last_status)
            newest = self._ring[-1].t_host_s if self._ring else None
            drift = self._state.health(self._ring[-1].field_ut if self._ring else None)
        rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 2 and times[-1] > times[0] else math.nan
        uptime = now - self._t_connect if self._connected else 0.0
        link = {"link_up": self._connected, **self._link_health()}
        cpu = link.get("reader_cpu_s", 0.0)
        return SensorHealth(source=self._source, connected=self._connected, rate_hz=rate,
                            last_frame_age_s=math.inf if newest is None else now - newest, uptime_s=uptime,
                            reader_cpu_fraction=cpu / uptime if uptime > 0 else 0.0, **base, **link, **drift)

    # ------------------------------------------------------------------ for backends

    def _publish(self, raw_ut: np.ndarray, saturated: np.ndarray, *, seq: int, t_host_s: float,
                 t_device_s: float = math.nan, status: int = 0, temperature_c: np.ndarray | None = None,
                 wire: bytes | None = None) -> TactileReading:
        """Make a reading from a raw ``layout.shape`` float32 field and hand it to readers (producer thread)."""
        raw_ut.flags.writeable = False
        saturated.flags.writeable = False
        with self._cond:
            state = self._state
            field = raw_ut if state.offset_ut is None else state.field(raw_ut, temperature_c)
            reading = TactileReading(field_ut=field, field_raw_ut=raw_ut, saturated=saturated, t_host_s=t_host_s,
                                     t_device_s=t_device_s, seq=seq, temperature_c=temperature_c)
            if state.config.track:
                state.observe(raw_ut, field)
            if self._last_seq is not None and not self._new_session:
                step = seq - self._last_seq
                if step > 1:
                    self._gaps += 1
                    self._missed += step - 1
                elif step <= 0:
                    self._resets += 1
            self._new_session = False
            self._last_seq = seq
            self._frames += 1
            self._last_status = status
            self._ring.append(reading)
            self._cond.notify_all()
            subs = self._subs
        if subs:
            item = SensorFrame(reading, status, wire)
            for sub in subs:
                sub._put(item)
        return reading

    def _collect(self, n: int, timeout_s: float) -> list[TactileReading]:
        """The next ``n`` frames in order (for a baseline); raises SensorTimeoutError after ``timeout_s``."""
        got: list[TactileReading] = []
        deadline = time.monotonic() + timeout_s
        with self.subscribe(max_frames=n + 64) as sub:
            while len(got) < n:
                try:
                    got.append(sub.get(deadline - time.monotonic()).reading)
                except SensorTimeoutError:
                    raise SensorTimeoutError(self._stale_message(
                        f"a baseline needs {n} frames but only {len(got)} arrived in {timeout_s:.1f} s")) from None
        return got

    def _use_baseline(self, baseline: Baseline | None) -> Baseline | None:
        """Switch baselines and re-express the buffered readings, so every reading returned from now on uses it."""
        with self._cond:
            self._baseline = baseline
            self._state.set(None if baseline is None else baseline.offset_ut,
                            None if baseline is None else baseline.temperature_c)
            for i, r in enumerate(self._ring):
                self._ring[i] = dataclasses.replace(r, field_ut=self._state.field(r.field_raw_ut, r.temperature_c))
        return baseline

    def _start_session(self) -> None:
        """The source was (re)opened: the next frame's counter step is not a gap."""
        with self._cond:
            self._new_session = True

    def _stale_message(self, what: str) -> str:
        link = self._link_health()
        err = link.get("last_error") or ""
        msg = f"{what} from {self._source}: {self._stale_hint()}"
        return f"{msg} (last error: {err})" if err else msg

    def _require_connected(self) -> None:
        if not self._connected:
            raise SensorDisconnectedError(f"{self._source} is not connected: call connect() first "
                                          "(or use the sensor as a context manager)")

    def _unsubscribe(self, sub: FrameSubscription) -> None:
        with self._cond:
            self._subs = tuple(s for s in self._subs if s is not sub)

    def _tail_within(self, span_s: float) -> list[TactileReading]:
        """Readings of the ring whose host time is within ``span_s`` of the newest, oldest first (lock held)."""
        out: list[TactileReading] = []
        if self._ring:
            t_end = self._ring[-1].t_host_s
            for r in reversed(self._ring):
                if t_end - r.t_host_s > span_s:
                    break
                out.append(r)
        return out[::-1]

    def _reset_counters(self) -> None:
        self._frames = self._gaps = self._missed = self._resets = self._last_status = 0
        self._last_seq: int | None = None
        self._new_session = True
        self._seen_seq = -1
        self._t_connect = time.monotonic()
