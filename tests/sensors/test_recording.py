"""Recordings: the crash-safe file format, the recorder (killed with SIGKILL too) and the replay sensor."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from tactile_manip.errors import RecordingError, SensorTimeoutError
from tactile_manip.sensors import ReplaySensor, ReplaySensorConfig, RecordingWriter, read_recording
from tactile_manip.wire.protocol import encode_frame
from tactile_manip.sensors.recording import MAGIC

CHIP = {"lsb_xy_ut": 0.2, "lsb_z_ut": 0.323, "saturation_counts": 32767}


def _write(path, n=10, *, temperature=False):
    rng = np.random.default_rng(0)
    counts = rng.integers(-30000, 30000, (n, 4, 4, 3))
    with RecordingWriter(path, {"source": "test", "chip": CHIP}) as w:
        for i in range(n):
            temps = np.full((4, 4), 2500 + i) if temperature else None
            w.write_frame(100.0 + i * 0.008, encode_frame(counts[i], seq=65530 + i, t_mcu_us=2**32 - 8000 + 8000 * i,
                                                          status=i, temperature_raw=temps))
            if i == 4:
                w.write_health(100.04, {"frames": 5, "rate_hz": float("nan")})
                w.write_event(100.04, {"event": "note"})
    return counts


def test_round_trip_unwraps_and_keeps_everything(tmp_path):
    counts = _write(tmp_path / "a.tmrec", temperature=True)
    rec = read_recording(tmp_path / "a.tmrec")
    assert len(rec) == 10 and rec.truncated_bytes == 0
    assert rec.header["source"] == "test" and rec.header["format_version"] == 1 and "code_version" in rec.header
    assert rec.seq.tolist() == list(range(65530, 65540))                     # unwrapped across 2**16
    assert np.allclose(np.diff(rec.t_device_s), 0.008)                       # unwrapped across 2**32 us
    assert np.allclose(rec.t_host_s, 100.0 + 0.008 * np.arange(10))
    assert np.array_equal(rec.counts, counts) and rec.status.tolist() == list(range(10))
    assert np.allclose(rec.field_raw_ut()[..., 2], counts[..., 2] * 0.323, rtol=1e-6)
    assert np.allclose(rec.temperature_c[:, 0, 0], 25.0 + 0.01 * np.arange(10))
    assert rec.health[0]["frames"] == 5 and rec.health[0]["t_host_s"] == 100.04
    assert rec.events == [{"t_host_s": 100.04, "event": "note"}]


def test_a_torn_tail_is_tolerated_at_every_cut(tmp_path):
    _write(tmp_path / "a.tmrec")
    data = (tmp_path / "a.tmrec").read_bytes()
    record = 2 + 2 + 8 + 110 + 4
    for cut in range(len(data) - 2 * record, len(data)):
        (tmp_path / "cut.tmrec").write_bytes(data[:cut])
        rec = read_recording(tmp_path / "cut.tmrec")
        complete = 10 - (len(data) - cut + record - 1) // record
        assert len(rec) == complete and rec.seq[-1] == 65530 + complete - 1
        assert rec.truncated_bytes == cut - (len(data) - (10 - complete) * record)
    (tmp_path / "zeros.tmrec").write_bytes(data + bytes(300))              # power loss: a zero-filled tail
    rec = read_recording(tmp_path / "zeros.tmrec")
    assert len(rec) == 10 and rec.truncated_bytes == 300


def test_bad_files_are_refused_clearly(tmp_path):
    with pytest.raises(RecordingError, match="not found"):
        read_recording(tmp_path / "missing.tmrec")
    (tmp_path / "x.npz").write_bytes(b"PK\x03\x04 not a recording")
    with pytest.raises(RecordingError, match="not a tactile_manip recording"):
        read_recording(tmp_path / "x.npz")
    (tmp_path / "new.tmrec").write_bytes(MAGIC + json.dumps({"format_version": 99}).encode() + b"\n")
    with pytest.raises(RecordingError, match="upgrade tactile_manip"):
        read_recording(tmp_path / "new.tmrec")
    (tmp_path / "torn.tmrec").write_bytes(MAGIC + b'{"format_ver')
    with pytest.raises(RecordingError, match="header"):
        read_recording(tmp_path / "torn.tmrec")


def test_the_recorder_keeps_every_frame_and_health(sim_recording):
    rec = read_recording(sim_recording)
    assert 100 <= len(rec) <= 200 and np.all(np.diff(rec.seq) == 1) and rec.truncated_bytes == 0
    assert rec.header["backend"] == "SimulatedSensor" and rec.header["chip"]["lsb_z_ut"] == 0.323
    assert len(rec.health) >= 1 and rec.health[-1]["frames"] >= len(rec) - 5
    assert np.allclose(np.diff(rec.t_device_s), 0.008, atol=1e-6)


def test_replay_at_recorded_pace_reproduces_the_frames(sim_recording):
    rec = read_recording(sim_recording)
    s = ReplaySensor(ReplaySensorConfig(path=str(sim_recording)))
    with s, s.subscribe() as sub:
        got = [sub.get(2.0).reading for _ in range(len(rec) - 1)]         # the first is published by connect
        t = [r.t_host_s for r in got]
    assert [r.seq for r in got] == rec.seq[1:].tolist()
    assert np.allclose(np.stack([r.field_raw_ut for r in got]), rec.field_raw_ut()[1:])
    assert np.allclose([r.t_device_s for r in got], rec.t_device_s[1:])
    assert abs((t[-1] - t[0]) - (rec.t_host_s[-1] - rec.t_host_s[1])) < 0.1  # recorded timing


def test_replay_on_demand_steps_one_frame_per_call_and_loops(sim_recording):
    rec = read_recording(sim_recording)
    n = len(rec)
    with ReplaySensor(ReplaySensorConfig(path=str(sim_recording), pace="on_demand")) as s:
        seqs = [s.wait_new(0.1).seq for _ in range(n - 1)] + [s.read_latest(0.1).seq]
        assert seqs == rec.seq.tolist() and s.finished
        with pytest.raises(SensorTimeoutError, match="end of the recording"):
            s.wait_new(0.1)
    with ReplaySensor(ReplaySensorConfig(path=str(sim_recording), pace="on_demand", loop=True)) as s:
        b = s.calibrate_baseline(20)
        assert b.frames == 20
        seqs = [s.wait_new(0.1).seq for _ in range(n + 5)]
        assert np.all(np.diff(seqs) == 1)                                  # unwrapped across the loop


def test_sigkill_leaves_every_frame_up_to_a_second_before(emulator, tmp_path, wait_until):
    e = emulator("--duration-s", "60")
    out = tmp_path / "rec.tmrec"
    rec_proc = subprocess.Popen([sys.executable, "-m", "tactile_manip", "record", "--port", e.path, "--out", str(out),
                                 "--quiet"], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)
    try:
        assert wait_until(lambda: out.exists() and out.stat().st_size > 125 * 126, 60.0)  # > ~1 s of frames
        time.sleep(1.5)
        t_kill = time.monotonic()
        os.kill(rec_proc.pid, signal.SIGKILL)
        rec_proc.wait(timeout=10)
    finally:
        if rec_proc.poll() is None:
            rec_proc.kill()
    rec = read_recording(out)
    assert len(rec) > 200 and np.all(np.diff(rec.seq) == 1)
    assert rec.t_host_s[-1] >= t_kill - 1.0, f"last frame {t_kill - rec.t_host_s[-1]:.2f} s before the kill"
    assert len(rec.health) >= 1 and rec.header["source"] == e.path


def test_a_flipped_byte_in_the_middle_loses_only_that_record(tmp_path):
    """Resync as the serial decoder does: the frames after a damaged record are read, and the damage counted."""
    counts = _write(tmp_path / "a.tmrec")
    data = bytearray((tmp_path / "a.tmrec").read_bytes())
    clean = read_recording(tmp_path / "a.tmrec")
    record = 2 + 2 + 8 + 110 + 4
    # frame 2: the third FR record after the header line (frames 0-4 come before the health and event records)
    start = data.index(b"FR", data.index(b"\n", len(MAGIC)) + 1)
    for _ in range(2):
        start = data.index(b"FR", start + record)
    for where in (start, start + 20, start + record - 1):  # the tag, the payload, the CRC of frame 2
        damaged = bytearray(data)
        damaged[where] ^= 0x10
        (tmp_path / "d.tmrec").write_bytes(bytes(damaged))
        rec = read_recording(tmp_path / "d.tmrec")
        assert len(rec) == 9 and rec.truncated_bytes == 0, where
        assert rec.seq.tolist() == [s for s in clean.seq.tolist() if s != 65532]
        assert rec.skipped_bytes == record and rec.damaged_records == 1
        assert np.array_equal(rec.counts[2:], counts[3:])
        assert len(rec.health) == 1 and len(rec.events) == 1  # the records after the damage are all there
    undamaged = read_recording(tmp_path / "a.tmrec")
    assert undamaged.skipped_bytes == 0 and undamaged.damaged_records == 0


def test_replay_reports_skipped_damage_as_crc_errors_and_resync_bytes(tmp_path):
    _write(tmp_path / "a.tmrec")
    data = bytearray((tmp_path / "a.tmrec").read_bytes())
    data[data.index(b"FR", data.index(b"\n", len(MAGIC)) + 1) + 30] ^= 0xFF
    (tmp_path / "d.tmrec").write_bytes(bytes(data))
    with ReplaySensor(ReplaySensorConfig(path=str(tmp_path / "d.tmrec"), pace="on_demand")) as sensor:
        h = sensor.health()
        assert h.crc_errors == 1 and h.resync_bytes == 2 + 2 + 8 + 110 + 4
