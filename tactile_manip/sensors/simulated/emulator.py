"""Firmware emulator: the MBTS board's byte stream on a pseudo-terminal, from the simulator, with faults.

It opens a pty (``os.openpty``, slave in raw mode), and writes one wire frame per tick at 125 Hz on a
monotonic schedule (sleep until the next deadline: no drift, no busy loop). The field is the simulated
sensor's idle baseline plus, during scripted presses, their change precomputed before streaming
(:mod:`tactile_manip.sensors.simulated.contacts`), with fresh chip noise each frame. Faults, each seeded:

- ``bit_flip_rate``, ``drop_byte_rate``, ``truncate_rate``: per-frame probabilities of one flipped bit, one
  missing byte, or the frame cut short; every frame touched is listed in ``EmulatorReport.corrupted_seqs``;
- ``stalls``: windows ``(start_s, duration_s)`` without any frame (the counter continues without a gap);
- ``disconnects``: windows in which the pty is closed, like an unplugged board; it then returns as a new pty.
  A pty cannot be re-created at the same ``/dev/pts/N`` path, so a disconnect needs ``link``: a symlink that
  the emulator removes on disconnect and re-points at the new pty on return, so a driver configured with
  the link path reconnects to "the same port".

The master side is non-blocking: while nobody reads the port, bytes beyond the kernel's buffer are dropped
and counted (as a USB bridge does), so a missing reader never stalls the schedule. ``clock="host"`` puts
``time.monotonic_ns() // 1000`` (system-wide on Linux) in ``t_mcu_us`` just before each write, which lets a
reader on the same machine measure the write-to-read latency.

The emulated board is any board whose file describes its magnetic body and layer (``board``; default the
wire format's own board, ``supermag-4x4`` or ``anyskin-5``): the simulator models that board's skin and chips.
``wire_format="anyskin"`` streams the ReSkin/AnySkin binary sketch's bytes (per chip float32 t, x, y, z in the
chip's own axes, then CRLF; :mod:`tactile_manip.wire.anyskin`), with a temperature of 25 degC and 0.1 degC noise;
``"supermag"`` our frames, which carry the 16 chips of ``supermag-4x4``.

Run it with ``tactile-manip emulate``.
"""

from __future__ import annotations

import os
import sys
import threading
import time
import tty
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from tactile_manip.outputs import OutputPathError, check_writable_parent
from tactile_manip.sensors.simulated.contacts import ContactTimeline, Press
from tactile_manip.boards import Board, load_board
from tactile_manip.sim.pair import SensorPair
from tactile_manip.wire import DEFAULT_LAYOUTS
from tactile_manip.wire.anyskin import pack_frame
from tactile_manip.wire.protocol import encode_frame

REBASE_LATE_S = 0.25  # a tick this late restarts the schedule instead of bursting to catch up


def _check_rate(name: str, value: float) -> None:
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"FaultConfig.{name} must be a probability in [0, 1], got {value}")


def _check_windows(name: str, windows: Sequence[tuple[float, float]]) -> None:
    for w in windows:
        if len(w) != 2 or w[0] < 0 or w[1] <= 0:
            raise ValueError(f"FaultConfig.{name}: each window must be (start_s >= 0, duration_s > 0), got {w}")


@dataclass(frozen=True)
class FaultConfig:
    """Faults the emulator injects (see the module docstring)."""

    bit_flip_rate: float = 0.0   # probability per frame of one flipped bit, anywhere in the frame
    drop_byte_rate: float = 0.0  # probability per frame of one missing byte
    truncate_rate: float = 0.0   # probability per frame of being cut short (the rest is never sent)
    stalls: tuple[tuple[float, float], ...] = ()       # (start_s, duration_s) without frames, s
    disconnects: tuple[tuple[float, float], ...] = ()  # (start_s, duration_s) with the port gone, s

    def __post_init__(self) -> None:
        for name in ("bit_flip_rate", "drop_byte_rate", "truncate_rate"):
            _check_rate(name, getattr(self, name))
        _check_windows("stalls", self.stalls)
        _check_windows("disconnects", self.disconnects)


@dataclass(frozen=True)
class EmulatorConfig:
    """What the emulated board streams, for how long, and where."""

    rate_hz: float = 125.0                 # frame rate, Hz
    seed: int = 0                          # chip noise and fault draws
    temperature: bool = False              # send the 16 chip temperatures (flags bit 0)
    link: str | None = None                # symlink kept pointing at the current pty (needed for disconnects)
    frames: int | None = None              # stop after this many frames (None: no limit)
    duration_s: float | None = None        # stop after this long, s (None: no limit)
    clock: Literal["device", "host"] = "device"  # t_mcu_us: time on the schedule, or host monotonic at write
    period_s: float | None = None          # repeat the press script with this period, s
    wire_format: Literal["supermag", "anyskin"] = "supermag"  # the bytes: our frames or the AnySkin sketch's
    board: str = ""  # the emulated board (a name or a board file; "": the wire format's own board)

    def __post_init__(self) -> None:
        if self.wire_format not in ("supermag", "anyskin"):
            raise ValueError(f"EmulatorConfig.wire_format must be 'supermag' or 'anyskin', got {self.wire_format!r}")
        if self.board and self.wire_format == "supermag" and self.board != "supermag-4x4":
            raise ValueError(f"EmulatorConfig.board {self.board!r}: the supermag wire format carries the 16 chips of "
                             "supermag-4x4; give --wire-format anyskin for another board")
        try:
            emulated_board(self).require_simulation()
        except ValueError as e:  # ConfigError: unknown, a bad file, or no magnets to simulate
            raise ValueError(f"EmulatorConfig.board: {e}") from None
        if not self.rate_hz > 0:
            raise ValueError(f"EmulatorConfig.rate_hz must be > 0, got {self.rate_hz}")
        if self.clock not in ("device", "host"):
            raise ValueError(f"EmulatorConfig.clock must be 'device' or 'host', got {self.clock!r}")
        if self.frames is not None and self.frames < 1:
            raise ValueError(f"EmulatorConfig.frames must be >= 1, got {self.frames}")


@dataclass
class EmulatorReport:
    """What the emulator did.

    ``corrupted_seqs`` lists the frame counters of every frame it damaged on purpose; ``overflow_seqs`` those
    the pty could not take whole (nobody reading, or a reader too slow), which a reader cannot get either.
    """

    frames_sent: int = 0
    corrupted_seqs: list[int] = field(default_factory=list)
    overflow_seqs: list[int] = field(default_factory=list)
    bit_flips: int = 0
    dropped_bytes: int = 0
    truncated_frames: int = 0
    stalls: int = 0
    disconnects: int = 0
    tx_overflow_bytes: int = 0
    late_rebases: int = 0
    last_seq: int = -1


def emulated_board(config: EmulatorConfig) -> Board:
    """The board ``config`` emulates: its ``board``, else the wire format's own."""
    return load_board(config.board or DEFAULT_LAYOUTS[config.wire_format])


def anyskin_frame(raw_pad_ut: np.ndarray, board: Board, rng: np.random.Generator) -> bytes:
    """An AnySkin sketch frame of ``board``'s chips from their (n_chips, 3) raw field in pad axes, uT (firmware
    order): each chip's vector turned into its own axes."""
    temps = 25.0 + 0.1 * rng.standard_normal(board.n_chips)
    chips_ut = np.einsum("nji,nj->ni", board.chip_matrices(), np.asarray(raw_pad_ut, np.float64))
    return pack_frame(temps, chips_ut)


class FirmwareEmulator:
    """An emulated MBTS board on a pty.

    Args:
        config: rate, seed, duration, link path, clock.
        presses: scripted contacts, solved in :meth:`open` before streaming starts.
        faults: injected faults.
        pair: the simulated sensor pair (default: the emulated board's, ``SensorPair(board=..., seed=config.seed)``).
    """

    def __init__(self, config: EmulatorConfig | None = None, *, presses: Sequence[Press] = (),
                 faults: FaultConfig | None = None, pair: SensorPair | None = None) -> None:
        self.config = config or EmulatorConfig()

        self.faults = faults or FaultConfig()
        if self.faults.disconnects and not self.config.link:
            raise ValueError("disconnects need a link path (EmulatorConfig.link / --link PATH): a pty cannot "
                             "come back at the same /dev/pts path, the link can")
        self.presses = tuple(presses)
        self.board = emulated_board(self.config)
        self.pair = pair if pair is not None else SensorPair(board=self.board, seed=self.config.seed)
        if self.pair.board.n_chips != self.board.n_chips:
            raise ValueError(f"the pair simulates board {self.pair.board.name}, the emulator streams {self.board.name}")
        self.report = EmulatorReport()
        self._timeline: ContactTimeline | None = None
        self._master = self._slave = -1
        self.device: str | None = None

    @property
    def path(self) -> str:
        """The path a driver should open: the link if configured, else the pty's slave device."""
        if self.device is None:
            raise RuntimeError("the emulator is not open: call open() first")
        return self.config.link or self.device

    def open(self) -> str:
        """Solve the press script, create the pty (and link); return :attr:`path`.

        Raises:
            OutputPathError: the link path holds something other than a pty link (a file, a folder, a link to
                anything else): the emulator never replaces or deletes what it did not create.
        """
        self._check_link()
        if self.presses and self._timeline is None:
            self._timeline = ContactTimeline(self.pair, self.presses, period_s=self.config.period_s,
                                             seed=self.config.seed)
        self._open_pty()
        return self.path

    def close(self) -> None:
        """Close the pty and remove the link."""
        self._close_pty()

    def __enter__(self) -> FirmwareEmulator:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ streaming

    def run(self, stop: threading.Event | None = None) -> EmulatorReport:
        """Stream until the frame or time budget is spent or ``stop`` is set; return the report (port still open)."""
        if self.device is None:
            self.open()
        stop = stop or threading.Event()
        cfg, rep = self.config, self.report
        period = 1.0 / cfg.rate_hz
        noise_rng = np.random.default_rng([cfg.seed, 0])
        fault_rng = np.random.default_rng([cfg.seed, 1])
        windows = sorted([(s, d, "stall") for s, d in self.faults.stalls]
                         + [(s, d, "disconnect") for s, d in self.faults.disconnects])
        t_start = time.monotonic()
        next_t, seq = t_start, 0
        while not stop.is_set():
            t_rel = next_t - t_start
            if (cfg.frames is not None and seq >= cfg.frames) or (cfg.duration_s is not None
                                                                  and t_rel >= cfg.duration_s):
                break
            wait = next_t - time.monotonic()
            if wait > 0 and stop.wait(wait):
                break
            if windows and t_rel >= windows[0][0]:
                start, duration, kind = windows.pop(0)
                self._outage(kind, t_start + start + duration, stop)
                next_t = max(t_start + start + duration, time.monotonic())
                continue
            if time.monotonic() - next_t > REBASE_LATE_S:
                next_t = time.monotonic()
                rep.late_rebases += 1
            self._send(seq, t_rel, noise_rng, fault_rng)
            seq += 1
            next_t += period
        rep.last_seq = seq - 1
        return rep

    def frame_bytes(self, seq: int, t_rel_s: float, noise_rng: np.random.Generator) -> bytes:
        """The undamaged frame ``seq`` at stream time ``t_rel_s`` (fresh noise from ``noise_rng``)."""
        change = self._timeline.chip_change_at(t_rel_s) if self._timeline is not None else 0.0
        measured = self.pair.chips.measure(self.pair.baseline_field_ut + change, noise_rng)
        if self.config.wire_format == "anyskin":
            return anyskin_frame(measured.raw_ut, self.board, noise_rng)
        counts = self.pair.to_reading(measured.counts)
        temps = None
        if self.config.temperature:
            temps = np.rint(2500 + 10 * noise_rng.standard_normal((4, 4))).astype(np.int16)  # 25 C, 0.1 C noise
        if self.config.clock == "host":
            t_us = time.monotonic_ns() // 1000
        else:
            t_us = int(round(t_rel_s * 1e6))
        return encode_frame(counts, seq=seq, t_mcu_us=t_us, temperature_raw=temps)

    def _send(self, seq: int, t_rel: float, noise_rng: np.random.Generator, fault_rng: np.random.Generator) -> None:
        data = self._damage(self.frame_bytes(seq, t_rel, noise_rng), seq, fault_rng)
        try:
            written = os.write(self._master, data)
        except BlockingIOError:
            written = 0
        except OSError:  # the pty went away under us; the next outage or close() cleans up
            written = 0
        if written < len(data):
            self.report.tx_overflow_bytes += len(data) - written
            self.report.overflow_seqs.append(seq)
        self.report.frames_sent += 1

    def _damage(self, frame: bytes, seq: int, rng: np.random.Generator) -> bytes:
        f, rep = self.faults, self.report
        draws = rng.random(3)  # always three draws per frame, so the fault sequence depends only on the seed
        data = bytearray(frame)
        if draws[0] < f.bit_flip_rate:
            bit = int(rng.integers(len(data) * 8))
            data[bit // 8] ^= 1 << (bit % 8)
            rep.bit_flips += 1
        if draws[1] < f.drop_byte_rate:
            del data[int(rng.integers(len(data)))]
            rep.dropped_bytes += 1
        if draws[2] < f.truncate_rate:
            data = data[:int(rng.integers(1, len(data)))]
            rep.truncated_frames += 1
        if (draws < [f.bit_flip_rate, f.drop_byte_rate, f.truncate_rate]).any():
            rep.corrupted_seqs.append(seq)
        return bytes(data)

    def _outage(self, kind: str, until: float, stop: threading.Event) -> None:
        log = f"{kind} for {until - time.monotonic():.2f} s"
        print(f"emulator: {log}", file=sys.stderr, flush=True)
        if kind == "disconnect":
            self.report.disconnects += 1
            self._close_pty()
            stop.wait(max(0.0, until - time.monotonic()))
            self._open_pty()
            print(f"emulator: back on {self.device}", file=sys.stderr, flush=True)
        else:
            self.report.stalls += 1
            stop.wait(max(0.0, until - time.monotonic()))

    # ------------------------------------------------------------------ the pty

    def _open_pty(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # binary-safe: no echo, no CR/LF translation, no signal characters
        os.set_blocking(self._master, False)
        self.device = os.ttyname(self._slave)
        if self.config.link:
            tmp = f"{self.config.link}.{os.getpid()}.tmp"
            os.symlink(self.device, tmp)
            os.replace(tmp, self.config.link)  # atomic: a driver never sees a half-made link

    def _check_link(self) -> None:
        link = self.config.link
        if not link:
            return
        check_writable_parent(link)
        if not os.path.lexists(link):
            return
        # a link to a pty is one an emulator made (and a killed one left behind); anything else is the user's
        if not (os.path.islink(link) and _is_pty_path(os.readlink(link))):
            raise OutputPathError(f"--link {link} exists and is not an emulator's pty link: refusing to replace "
                                  "a file the emulator did not create; give another path")

    def _close_pty(self) -> None:
        link = self.config.link
        if link and os.path.islink(link) and os.readlink(link) == self.device:  # only the link this run made
            os.unlink(link)
        for fd in (self._master, self._slave):
            if fd >= 0:
                os.close(fd)
        self._master = self._slave = -1


def _is_pty_path(path: str) -> bool:
    """Whether ``path`` names a pseudo-terminal device (Linux ``/dev/pts/N``, macOS ``/dev/ttysNNN``)."""
    return path.startswith("/dev/pts/") or (path.startswith("/dev/ttys") and path[9:].isdigit())
