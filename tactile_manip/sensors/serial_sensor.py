"""The serial backend: the real MBTS board (or the firmware emulator's pty) read with pyserial.

A reader thread blocks in ``Serial.read`` with a timeout (no busy loop), feeds the bytes to the protocol
decoder of the configured wire format (:mod:`tactile_manip.wire`) and publishes each valid frame
through the board layout (:class:`~tactile_manip.boards.Board`). The port is opened exclusively with DTR and
RTS at the configured levels (low by default: ESP32 boards behind a USB bridge reset, or enter their
bootloader, when the host raises them; native-USB boards such as the SAMD21 only write once DTR is high),
found by its device path or by its USB serial number on every (re)open; the first frames after every
(re)open are dropped, and an error on the port closes it and reopens it with exponential back-off. Formats
without a counter or clock get a host-side sequence (+1 per frame) and a NaN device time. pyserial is
imported on ``connect()`` only, so ``import tactile_manip.sensors`` works without it.
"""

from __future__ import annotations

import math
import os
import threading
import time
from typing import Any


from tactile_manip.errors import SensorDisconnectedError, SensorTimeoutError
from tactile_manip.extras import require
from tactile_manip.sensors.base import TactileSensor
from tactile_manip.sensors.config import SerialSensorConfig
from tactile_manip.boards import load_board
from tactile_manip.wire.protocol import Unwrapper
from tactile_manip.wire import ChipFrame, make_decoder


def import_serial() -> Any:
    """Return the pyserial module, or raise a MissingExtraError (an ImportError) naming the extra."""
    return require("serial", "the serial sensor backend")


class SerialSensor(TactileSensor):
    """An MBTS board on a serial port (see :class:`~tactile_manip.sensors.base.TactileSensor` for the contract).

    Several boards work as several instances (one port and one reader thread each); see
    :class:`~tactile_manip.sensors.array.SensorArray`.

    Args:
        config: port, baud rate, timeouts, back-off, chip LSBs and baseline settings.
    """

    def __init__(self, config: SerialSensorConfig) -> None:
        super().__init__(source=config.source, chip=config.chip, buffer_frames=config.buffer_frames,
                         baseline=config.baseline, layout=load_board(config.layout), drift=config.drift)
        self.config = config
        self._stop = threading.Event()
        self._port_lock = threading.Lock()
        self._port: Any = None
        self._thread: threading.Thread | None = None
        self._reset_link_counters()

    @property
    def wire_format(self) -> str:
        return self.config.wire_format

    def check_port(self) -> None:
        """Fail now, opening nothing, where :meth:`connect` would fail for certain: before a caller starts long
        work or writes files on the board's behalf. A port that passes may still fail to open (held by another
        program, no permission); ``connect()`` says why.

        Raises:
            MissingExtraError: pyserial is not installed (an ImportError naming the extra).
            SensorDisconnectedError: the configured device path does not exist, or no connected USB port has
                the configured serial number.
        """
        import_serial()
        device = self._device()  # by serial number: the port that has it now, or SensorDisconnectedError
        if os.path.isabs(device) and not os.path.exists(device):  # COM3 and the like are not paths: left to open
            raise SensorDisconnectedError(f"{device} does not exist: is the board plugged in? "
                                          "`tactile-manip find-port` lists the ports")

    # ------------------------------------------------------------------ TactileSensor hooks

    def _open(self) -> None:
        serial = import_serial()
        self._reset_link_counters()
        self._stop.clear()
        self._port = self._open_port(serial)
        self._begin_session()
        self._thread = threading.Thread(target=self._run, args=(serial,), daemon=True,
                                        name=f"tactile-serial {self.config.source}")
        self._thread.start()
        with self._cond:
            if self._cond.wait_for(lambda: self._frames > 0, timeout=self.config.connect_timeout_s):
                return
        raise SensorTimeoutError(self._no_frame_message())

    def _close(self) -> None:
        self._stop.set()
        with self._port_lock:
            port = self._port
        if port is not None:
            try:
                port.cancel_read()
            except Exception:  # noqa: BLE001 - best effort: the join below has a timeout anyway
                pass
        self._stop_producer()
        self._close_port()

    def _link_health(self) -> dict[str, Any]:
        st = self._decoder.stats
        return {"link_up": self._connected and self._port is not None, "crc_errors": st.crc_errors,
                "version_errors": st.version_errors, "frame_errors": st.frame_errors,
                "resync_bytes": st.resync_bytes,
                "dropped_at_start": self._dropped, "reconnects": self._reconnects, "reader_cpu_s": self._cpu_s,
                "last_error": self._last_error}

    def _stale_hint(self) -> str:
        hint = "is the board powered and streaming? run `tactile-manip find-port`"
        if self._connected and self._port is None:
            hint += f"; the port is closed and being reopened ({self._failed_reopens} failed attempts so far)"
        return hint

    # ------------------------------------------------------------------ the reader thread

    def _run(self, serial: Any) -> None:
        cfg = self.config
        cpu0 = time.thread_time()
        backoff = cfg.reconnect_min_s
        while not self._stop.is_set():
            try:
                port = self._port
                if port is None:
                    if not cfg.reconnect or self._stop.wait(backoff):
                        break
                    if self._reopen(serial):
                        backoff = cfg.reconnect_min_s
                    else:
                        backoff = min(2.0 * backoff, cfg.reconnect_max_s)
                    continue
                # Block for the first byte, then take what else arrived with it: one wake-up per frame.
                data = port.read(port.in_waiting or 1)
                if data:
                    more = port.in_waiting
                    self._on_bytes(data + port.read(more) if more else data, time.monotonic())
            except (serial.SerialException, OSError) as e:
                self._last_error = f"{type(e).__name__}: {e}"
                self._close_port()
            except Exception as e:  # noqa: BLE001 - the thread must survive anything and report it
                self._last_error = f"{type(e).__name__} in the reader thread: {e}"
                self._decoder.reset()
            finally:
                self._cpu_s = time.thread_time() - cpu0

    def _on_bytes(self, data: bytes, t_host_s: float) -> None:
        for frame in self._decoder.feed(data):
            if self._to_drop > 0:
                self._to_drop -= 1
                self._dropped += 1
                continue
            self._publish_frame(frame, t_host_s)

    def _publish_frame(self, f: ChipFrame, t_host_s: float) -> None:
        layout = self.layout
        if f.seq is None:  # the format has no counter: count frames on the host
            self._host_seq += 1
            seq = self._host_seq
        else:
            seq, _ = self._seq.update(f.seq)
        t_device_s = math.nan if f.t_device_us is None else self._clock.update(f.t_device_us)[0] * 1e-6
        temps = None if f.temperature_c is None else layout.cells_from_chips(f.temperature_c)
        self._publish(layout.reading_from_chips(f.field_ut), layout.saturation_from_chips(f.saturated), seq=seq,
                      t_host_s=t_host_s, t_device_s=t_device_s, status=f.status, temperature_c=temps, wire=f.raw)

    # ------------------------------------------------------------------ the port

    def _open_port(self, serial: Any) -> Any:
        cfg = self.config
        port = serial.Serial()  # no port yet: nothing is opened before every setting is in place
        port.baudrate = cfg.baudrate
        port.timeout = cfg.read_timeout_s
        port.exclusive = cfg.exclusive
        # applied on open: ESP32 boards reset (or enter the bootloader) on DTR/RTS high, native-USB boards
        # (SAMD21) stay silent until DTR is high
        port.dtr = cfg.dtr
        port.rts = cfg.rts
        port.port = self._device()
        try:
            port.open()
        except (serial.SerialException, OSError, ValueError) as e:
            raise SensorDisconnectedError(
                f"cannot open {port.port}: {e}. Is the board plugged in? `tactile-manip find-port` lists the "
                "ports; if another program holds this one (the port is opened exclusively), close it") from e
        return port

    def _device(self) -> str:
        """The device path to open: the configured port, or the port that has the configured serial number now."""
        cfg = self.config
        if cfg.port:
            return cfg.port
        from tactile_manip.sensors.ports import device_for_serial_number  # ports imports this module

        return device_for_serial_number(cfg.serial_number)

    def _reopen(self, serial: Any) -> bool:
        try:
            port = self._open_port(serial)
        except SensorDisconnectedError as e:
            self._failed_reopens += 1
            self._last_error = f"reopening: {e.__cause__ or e}"
            return False
        with self._port_lock:
            if self._stop.is_set():
                port.close()
                return False
            self._port = port
        self._reconnects += 1
        self._begin_session()
        return True

    def _close_port(self) -> None:
        with self._port_lock:
            port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except Exception:  # noqa: BLE001 - closing a vanished device may fail; it is gone either way
                pass

    def _begin_session(self) -> None:
        self._decoder.reset()
        self._to_drop = self.config.drop_first_frames
        self._start_session()

    def _reset_link_counters(self) -> None:
        cfg = self.config
        self._decoder = make_decoder(cfg.wire_format, n_chips=self.layout.n_chips, chip=cfg.chip)
        self._seq = Unwrapper(self._decoder.seq_bits or 16)
        self._clock = Unwrapper(self._decoder.clock_bits or 32)
        self._host_seq = -1
        self._to_drop = 0
        self._dropped = self._reconnects = self._failed_reopens = 0
        self._cpu_s = 0.0
        self._last_error = ""

    def _no_frame_message(self) -> str:
        cfg, st = self.config, self._decoder.stats
        if st.bytes_in == 0:
            why = "no bytes at all: is the board powered and running the streaming firmware?"
            if not cfg.dtr:
                why += (" A native-USB board (SAMD21, as on AnySkin) only writes once the host raises DTR: "
                        "set dtr=True (`--dtr high`).")
        else:
            why = f"{self._decoder.no_frame_hint()} (wire format {cfg.wire_format!r}, baud rate {cfg.baudrate})."
        err = f" (last error: {self._last_error})" if self._last_error else ""
        return (f"opened {cfg.source} but no valid frame arrived in {cfg.connect_timeout_s:.1f} s: {why} "
                f"`tactile-manip find-port` lists the ports{err}")
