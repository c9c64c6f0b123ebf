"""The TactileSensor contract, one test body run against every backend.

``serial`` is the real pyserial driver reading the firmware emulator (another process) through a pty,
``serial-anyskin`` the same driver reading the emulator's ReSkin/AnySkin stream (5 chips, no counter or clock),
``simulated`` the in-process simulator, ``replay`` a recording played at its recorded pace.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from tactile_manip.errors import SensorDisconnectedError, SensorError, SensorTimeoutError
from tactile_manip.sensors import (
    ReplaySensor,
    ReplaySensorConfig,
    SensorHealth,
    SerialSensor,
    SerialSensorConfig,
    SimulatedSensor,
    SimulatedSensorConfig,
    TactileSensor,
    make_sensor,
)

BACKENDS = ("serial", "serial-anyskin", "simulated", "replay")


def _factory(kind: str, request):
    if kind == "serial":
        path = request.getfixturevalue("streaming_emulator").path
        return lambda: make_sensor(SerialSensorConfig(port=path))
    if kind == "serial-anyskin":
        path = request.getfixturevalue("anyskin_emulator").path
        return lambda: make_sensor(SerialSensorConfig(port=path, wire_format="anyskin"))
    if kind == "simulated":
        return lambda: make_sensor(SimulatedSensorConfig(seed=3))
    path = str(request.getfixturevalue("sim_recording"))
    return lambda: make_sensor(ReplaySensorConfig(path=path, loop=True))


@pytest.fixture(params=BACKENDS)
def make(request):
    """A factory of unconnected sensors of one backend."""
    return _factory(request.param, request)


@pytest.fixture(params=("simulated", "replay"))
def make_in_process(request):
    """The backends whose staleness a test can trigger itself (the serial stall is the emulator's:
    test_serial_emulator.py)."""
    return _factory(request.param, request)


def test_backend_table_builds_each_class(make):
    s = make()
    assert isinstance(s, TactileSensor) and isinstance(s, (SerialSensor, SimulatedSensor, ReplaySensor))


def test_constructor_does_no_io_and_readers_need_a_connection(make):
    s = make()
    assert not s.is_connected
    for call in (lambda: s.read_latest(), lambda: s.wait_new(0.01), lambda: s.window(1),
                 lambda: s.calibrate_baseline(5)):
        with pytest.raises(SensorDisconnectedError, match="connect"):
            call()
    s.disconnect()  # idempotent when never connected


def test_readings_follow_the_documented_layout(make):
    with make() as s:
        r = s.wait_new(timeout_s=2.0)
        assert r.shape == s.layout.shape == ((3, 3, 3) if s.wire_format == "anyskin" else (4, 4, 3))
        assert r.field_ut.dtype == np.float32 and r.field_raw_ut.dtype == np.float32 and r.saturated.dtype == bool
        assert np.isfinite(r.field_raw_ut).all() and not r.saturated.any()
        assert np.array_equal(r.field_ut, r.field_raw_ut)               # no baseline yet: raw == field
        assert 1000 < float(np.abs(r.field_raw_ut[s.layout.mask, 2]).mean()) < 20000  # the magnet's idle field, uT
        assert r.t_host_s <= time.monotonic()
        if s.wire_format == "anyskin":  # no device clock on this wire; temperatures always sent
            assert np.isnan(r.t_device_s) and r.temperature_c.shape == s.layout.grid
            assert not r.field_raw_ut[~s.layout.mask].any()             # cells without a chip stay 0
        else:
            assert np.isfinite(r.t_device_s) and r.temperature_c is None
        with pytest.raises(ValueError):
            r.field_ut[0, 0, 0] = 1.0                                   # readings are immutable


def test_wait_new_and_read_latest_return_unseen_frames_in_order(make):
    with make() as s:
        a = s.wait_new(2.0)
        b = s.wait_new(2.0)
        assert b.seq > a.seq and b.t_host_s >= a.t_host_s
        c = s.read_latest(max_age_s=1.0)
        assert c.seq >= b.seq
        d = s.wait_new(2.0)
        assert d.seq > c.seq


def test_window_is_oldest_first_and_bounded(make):
    with make() as s:
        s.wait_new(2.0)
        time.sleep(0.2)
        w = s.window(10)
        assert 1 <= len(w) <= 10 and all(b.seq > a.seq for a, b in zip(w, w[1:]))
        assert w[-1].seq == s.read_latest(1.0).seq or w[-1].seq < s.read_latest(1.0).seq
        for bad in (0, 10**6, 2.5):
            with pytest.raises(ValueError, match="buffer_frames"):
                s.window(bad)


def test_health_reports_the_nominal_rate_and_no_gaps(make):
    with make() as s:
        s.wait_new(2.0)
        time.sleep(1.05)
        h = s.health()
        assert isinstance(h, SensorHealth) and h.connected and h.link_up
        assert h.frames > 60 and h.seq_gaps == 0 and h.frames_missed == 0 and h.crc_errors == 0
        assert abs(h.rate_hz - 125.0) < 0.15 * 125.0                     # loose here; the benchmark measures
        assert h.last_frame_age_s < 0.5 and h.reader_cpu_fraction < 0.5 and h.last_error == ""
    assert not s.health().connected


def test_baseline_rezero_and_clear(make):
    with make() as s:
        b = s.calibrate_baseline(40)
        assert b.frames == 40 and s.baseline is b
        recent = [s.wait_new(2.0) for _ in range(20)]
        for r in recent:
            assert np.allclose(r.field_ut, r.field_raw_ut - b.offset_ut, atol=1e-3)
        assert float(np.abs(np.mean([r.field_ut for r in recent], axis=0)).max()) < 5.0  # idle: ~0 after baseline
        assert s.rezero().frames == 40
        s.clear_baseline()
        r = s.wait_new(2.0)
        assert np.array_equal(r.field_ut, r.field_raw_ut)
        s.set_baseline(np.zeros(s.layout.shape))
        assert np.array_equal(s.read_latest(1.0).field_ut, s.read_latest(1.0).field_raw_ut)
        with pytest.raises(ValueError, match="shape"):
            s.set_baseline(np.zeros(48))


def test_context_manager_closes_and_double_connect_is_refused(make):
    s = make()
    with s:
        assert s.is_connected
        with pytest.raises(SensorError, match="already connected"):
            s.connect()
    assert not s.is_connected
    with pytest.raises(SensorDisconnectedError):
        s.wait_new(0.1)
    s.connect()                       # a sensor can be connected again after disconnecting
    try:
        assert s.wait_new(2.0).seq >= 0
    finally:
        s.disconnect()


def test_every_frame_reaches_a_subscriber_in_order(make):
    with make() as s, s.subscribe() as sub:
        frames = [sub.get(2.0) for _ in range(30)]
    seqs = [f.reading.seq for f in frames]
    assert seqs == list(range(seqs[0], seqs[0] + 30))


def test_staleness_raises_timeout_errors(make_in_process):
    with make_in_process() as s:
        s.wait_new(2.0)
        if isinstance(s, SimulatedSensor):
            s.stall()
        else:
            s.disconnect()
            s = ReplaySensor(ReplaySensorConfig(path=s.config.path, speed=8.0))  # plays out in ~0.15 s
            s.connect()
            time.sleep(0.6)
        time.sleep(0.15)
        with pytest.raises(SensorTimeoutError, match=r"no frame for 0\.\d\d s"):
            s.read_latest(max_age_s=0.1)
        try:
            s.wait_new(timeout_s=0.0)  # the last frame before the stall, if not returned yet, comes at once
        except SensorTimeoutError:
            pass
        t0 = time.monotonic()
        with pytest.raises(SensorTimeoutError, match="no new frame within 0.20 s"):
            s.wait_new(timeout_s=0.2)
        assert time.monotonic() - t0 >= 0.19
        s.disconnect()
