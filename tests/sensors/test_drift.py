"""Baseline tracking on a quiet pad, temperature compensation and the stray-field warning (sensors/drift.py)."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_manip.sensors import SerialSensorConfig, SimulatedSensor, SimulatedSensorConfig
from tactile_manip.sensors.config import DriftConfig
from tactile_manip.sensors.drift import BaselineState
from tactile_manip.boards import load_board


def _state(**kw) -> BaselineState:
    state = BaselineState(DriftConfig(**kw), load_board("supermag-4x4"))
    state.set(np.full((4, 4, 3), 100.0, np.float32), None)
    return state


def test_no_baseline_means_raw_and_no_tracking():
    state = BaselineState(DriftConfig(track=True), load_board("supermag-4x4"))
    raw = np.ones((4, 4, 3), np.float32)
    assert state.field(raw, None) is raw
    state.observe(raw, raw)
    assert state.health(raw)["baseline_updates"] == 0 and not state.health(raw)["stray_field"]


def test_tracking_follows_slow_drift_only_after_a_quiet_run_and_never_learns_a_press():
    rng = np.random.default_rng(0)
    state = _state(track=True, quiet_ut=15.0, quiet_frames=50, rate=0.05)
    raw = np.full((4, 4, 3), 100.0, np.float32)

    def frame(extra: float = 0.0, drift: float = 0.0) -> None:
        r = (raw + drift + extra + rng.normal(0, 1.0, raw.shape)).astype(np.float32)
        state.observe(r, state.field(r, None))

    for _ in range(50):
        frame()
    assert state.updates == 0 and not state.health(None)["baseline_tracking"]   # not yet quiet long enough
    for _ in range(400):
        frame(drift=8.0)                                                         # slow drift within quiet_ut
    assert state.health(None)["baseline_tracking"] and abs(float(state.offset_ut.mean()) - 108.0) < 0.5
    before = state.offset_ut.copy()
    press = np.zeros((4, 4, 3), np.float32)
    press[1:3, 1:3, 2] = 300.0
    for _ in range(100):
        frame(drift=8.0, extra=press)                                            # a press: loud frames
    np.testing.assert_array_equal(state.offset_ut, before)                       # nothing learnt
    assert not state.health(None)["baseline_tracking"]
    assert state.health(None)["baseline_moved_ut"] == pytest.approx(float(np.abs(before - 100.0).max()))


def test_tracking_is_off_by_default():
    state = _state()
    raw = np.full((4, 4, 3), 105.0, np.float32)
    for _ in range(500):
        state.observe(raw, state.field(raw, None))
    assert state.updates == 0 and state.health(None)["baseline_moved_ut"] == 0.0


def test_temperature_compensation_uses_per_chip_coefficients_in_firmware_order():
    coeff = np.zeros((5, 3))
    coeff[0] = [1.0, 0.0, 2.0]        # centre chip: +1 uT/degC on its x (the pad's y after its 90 degree turn)
    state = BaselineState(DriftConfig(temperature_coeff_ut_per_c=tuple(coeff.ravel())), load_board("anyskin-5"))
    t_ref = load_board("anyskin-5").cells_from_chips(np.full(5, 25.0))
    state.set(np.zeros((3, 3, 3), np.float32), t_ref)
    warm = load_board("anyskin-5").cells_from_chips(np.full(5, 30.0))
    raw = np.zeros((3, 3, 3), np.float32)
    raw[1, 1] = [0.0, 5.0, 10.0]      # what 5 degC of drift looks like on the centre chip, pad axes
    np.testing.assert_allclose(state.field(raw, warm), 0.0, atol=1e-5)
    np.testing.assert_allclose(state.field(raw, None)[1, 1], [0.0, 5.0, 10.0])  # no temperature: no term
    with pytest.raises(ValueError, match="needs 3 per chip \\(15\\)"):
        BaselineState(DriftConfig(temperature_coeff_ut_per_c=(1.0, 2.0, 3.0)), load_board("anyskin-5"))
    with pytest.raises(ValueError, match="3 values"):
        DriftConfig(temperature_coeff_ut_per_c=(1.0, 2.0))
    with pytest.raises(ValueError, match="supermag-4x4 board needs 3 per chip \\(48\\)"):
        SerialSensorConfig(port="/dev/ttyUSB0", drift=DriftConfig(temperature_coeff_ut_per_c=(0.0,) * 15))


def test_stray_field_flags_a_common_shift_not_a_local_press():
    state = _state(common_mode_ut=30.0)
    press = np.zeros((4, 4, 3), np.float32)
    press[1:3, 1:3, 2] = 500.0        # 4 of 16 chips: the median stays put
    assert not state.health(press)["stray_field"]
    magnet = np.zeros((4, 4, 3), np.float32)
    magnet[..., 2] = 45.0             # every chip shifted together
    h = state.health(magnet)
    assert h["stray_field"] and h["common_mode_ut"][2] == pytest.approx(45.0)


def test_health_of_a_sensor_reports_the_drift_fields():
    with SimulatedSensor(SimulatedSensorConfig(seed=2)) as s:
        assert np.isnan(s.health().common_mode_ut).all() and not s.health().stray_field
        s.calibrate_baseline(30)
        s.wait_new(1.0)
        h = s.health()
        assert np.isfinite(h.common_mode_ut).all() and not h.stray_field and not h.baseline_tracking
