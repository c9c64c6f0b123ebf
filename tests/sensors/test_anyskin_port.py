"""Acceptance: an AnySkin board's byte stream, written into a pty by a writer built here from the published
format (struct.pack of float32 t, x, y, z per chip, then CRLF; not our emulator's code), read by the serial
driver, recorded, replayed and viewed through the CLI.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import threading
import time
import tty

import numpy as np
import pytest

from tactile_manip.sensors import ReplaySensor, ReplaySensorConfig, SerialSensor, SerialSensorConfig, read_recording

N_CHIPS = 5
RATE_HZ = 125.0
NOISE = b"\x00\r\n\xff\x13\r\r\n" + bytes(range(40, 77))  # line endings in the wrong places, then junk
# where each chip of the board lands (centre, left, right, up, down) and its turn into the pad frame, deg
CELLS = [(1, 1), (1, 0), (1, 2), (0, 1), (2, 1)]
TURN_DEG = [90, 90, 180, -90, 0]


def chip_values(k: int) -> np.ndarray:
    """(5, 4) float32 t, x, y, z of frame k: distinct per chip and frame, so order and frame are checkable."""
    c = np.arange(N_CHIPS)
    return np.stack([20.0 + c + 0.25 * (k % 40), 100.0 * c + k, -50.0 * c - 2 * k, 1000.0 + 10 * c + k],
                    axis=1).astype(np.float32)


def expected_reading(k: int) -> np.ndarray:
    """(3, 3, 3) pad-frame reading of frame k, from the layout of the anyskin-5 board file."""
    v = chip_values(k)
    out = np.zeros((3, 3, 3), np.float32)
    for i, ((r, col), deg) in enumerate(zip(CELLS, TURN_DEG)):
        c, s = {0: (1, 0), 90: (0, 1), 180: (-1, 0), -90: (0, -1)}[deg]
        x, y = v[i, 1], v[i, 2]
        out[r, col] = (c * x - s * y, s * x + c * y, v[i, 3])
    return out


def frame_of(reading: np.ndarray) -> int:
    """Which frame k a reading is (chip 4, "down", is unrotated: its x is 400 + k)."""
    return int(round(float(reading[2, 1, 0]) - 400.0))


class AnySkinWriter:
    """A free-running AnySkin board on a pty: frames at RATE_HZ, optional noise bursts; drops when nobody reads."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.k = 0
        self.noise_after: set[int] = set()
        self.noisy_frames: list[int] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            data = b"".join(struct.pack("<4f", *row) for row in chip_values(self.k)) + b"\r\n"
            if self.k in self.noise_after:
                data = data[:37] + NOISE  # the frame is cut short and followed by junk
                self.noisy_frames.append(self.k)
            try:
                os.write(self.master, data)
            except BlockingIOError:
                pass
            self.k += 1
            next_t += 1.0 / RATE_HZ
            self._stop.wait(max(0.0, next_t - time.monotonic()))

    def __enter__(self) -> AnySkinWriter:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(2.0)
        os.close(self.master)
        os.close(self.slave)


def test_serial_sensor_reads_the_published_stream_exactly_and_resyncs_after_noise():
    with AnySkinWriter() as board:
        config = SerialSensorConfig(port=board.path, wire_format="anyskin", dtr=True, rts=True)
        with SerialSensor(config) as sensor, sensor.subscribe() as sub:
            first = sub.get(2.0).reading
            board.noise_after = {frame_of(first.field_raw_ut) + 40, frame_of(first.field_raw_ut) + 90}
            readings = [first] + [sub.get(2.0).reading for _ in range(159)]
            health = sensor.health()
    ks = [frame_of(r.field_raw_ut) for r in readings]
    for k, r in zip(ks, readings):
        np.testing.assert_array_equal(r.field_raw_ut, expected_reading(k))     # exact values, chip order, axes
        np.testing.assert_array_equal(r.temperature_c[1, 1], chip_values(k)[0, 0])
        assert np.isnan(r.t_device_s) and not r.saturated.any()
    assert [r.seq for r in readings] == list(range(readings[0].seq, readings[0].seq + 160))  # host sequence
    steps = np.diff(ks)
    # every frame arrives except the cut one and the one right after each noise burst (no line ending before it)
    assert set(steps.tolist()) <= {1, 2, 3} and int((steps > 1).sum()) == 2
    missing = [k for k in range(ks[0], ks[-1] + 1) if k not in ks]
    assert missing == sorted(k + i for k in board.noisy_frames for i in (0, 1))
    assert health.frame_errors == 2 and health.resync_bytes > len(NOISE) and health.crc_errors == 0
    assert health.last_error == ""                                        # the reader thread never raised


def test_a_silent_native_usb_board_gets_a_hint_about_dtr():
    master, slave = os.openpty()
    try:
        config = SerialSensorConfig(port=os.ttyname(slave), wire_format="anyskin", connect_timeout_s=0.3)
        with pytest.raises(Exception, match="raises DTR: set dtr=True"):
            SerialSensor(config).connect()
    finally:
        os.close(master)
        os.close(slave)


def _cli(*args: str, timeout_s: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "tactile_manip", *args], capture_output=True, text=True,
                          timeout=timeout_s)


def test_record_replay_and_view_work_on_the_stream(tmp_path):
    rec_path, png = tmp_path / "anyskin.tmrec", tmp_path / "live.png"
    with AnySkinWriter() as board:
        out = _cli("record", "--port", board.path, "--wire-format", "anyskin", "--dtr", "high", "--out",
                   str(rec_path), "--seconds", "1.5", "--quiet")
        assert out.returncode == 0, out.stderr
        live = _cli("view", "--port", board.path, "--wire-format", "anyskin", "--snapshot", str(png),
                    "--seconds", "0.5", "--no-baseline")
        assert live.returncode == 0, live.stderr
        assert png.stat().st_size > 0
    rec = read_recording(rec_path)
    assert rec.header["wire_format"] == "anyskin" and rec.header["layout"] == "anyskin-5"
    assert rec.counts is None and len(rec) > 100
    for i, reading in enumerate(rec.field_raw_ut()):
        np.testing.assert_array_equal(reading, expected_reading(frame_of(reading)))
    assert np.all(np.diff([frame_of(r) for r in rec.field_raw_ut()]) == 1)
    with ReplaySensor(ReplaySensorConfig(path=str(rec_path), pace="on_demand")) as replay:
        assert replay.layout.name == "anyskin-5"
        np.testing.assert_array_equal(replay.wait_new(0.1).field_raw_ut, rec.field_raw_ut()[0])
    snap = tmp_path / "replay.png"
    out = _cli("view", "--replay", str(rec_path), "--snapshot", str(snap), "--seconds", "0.5",
               "--no-baseline")
    assert out.returncode == 0, out.stderr
    assert snap.stat().st_size > 0
