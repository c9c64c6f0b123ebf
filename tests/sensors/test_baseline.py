"""Baseline calibration: accepted on idle frames, refused with a clear message on contact or saturation."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_manip.errors import CalibrationError
from tactile_manip.sensors.baseline import baseline_from_frames, noise_thresholds_ut
from tactile_manip.sensors.config import BaselineConfig
from tactile_manip.chips import MLX90393

THRESHOLDS = noise_thresholds_ut(BaselineConfig(), MLX90393)


def _idle(n=125, seed=0):
    rng = np.random.default_rng(seed)
    offset = rng.uniform(-5000, 5000, (4, 4, 3))
    noise = np.array([1.5, 1.5, 2.5])
    return offset, offset + rng.standard_normal((n, 4, 4, 3)) * noise


def test_thresholds_are_six_times_the_rated_noise_or_absolute():
    assert np.allclose(THRESHOLDS, [9.0, 9.0, 15.0])
    assert np.allclose(noise_thresholds_ut(BaselineConfig(max_noise_ut=20.0), MLX90393), 20.0)


def test_idle_frames_give_their_mean():
    offset, frames = _idle()
    b = baseline_from_frames(frames, np.zeros(frames.shape, bool), THRESHOLDS)
    assert b.offset_ut.dtype == np.float32 and b.offset_ut.shape == (4, 4, 3) and b.frames == 125
    assert np.abs(b.offset_ut - offset).max() < 1.5
    assert np.allclose(b.noise_ut.mean(axis=(0, 1)), [1.5, 1.5, 2.5], rtol=0.2)


def test_a_press_during_the_baseline_is_refused_with_the_noise_and_threshold():
    _, frames = _idle()
    frames[:, 1, 2, 2] += np.linspace(0.0, 150.0, len(frames))  # a press ramping up on one chip
    with pytest.raises(CalibrationError) as e:
        baseline_from_frames(frames, np.zeros(frames.shape, bool), THRESHOLDS, source="/dev/ttyUSB0")
    msg = str(e.value)
    assert "/dev/ttyUSB0" in msg and "chip (1, 2) axis z" in msg and "15.0 uT threshold" in msg
    assert "touching the pad" in msg and "rezero()" in msg
    std = float(np.std(frames[:, 1, 2, 2], ddof=1))
    assert f"noise {std:.1f} uT" in msg


def test_saturated_channels_are_refused():
    _, frames = _idle()
    sat = np.zeros(frames.shape, bool)
    sat[3, 0, 0, 1] = True
    with pytest.raises(CalibrationError, match=r"chip \(0, 0\) axis y is saturated"):
        baseline_from_frames(frames, sat, THRESHOLDS)


def test_config_validation_names_the_field():
    with pytest.raises(ValueError, match="BaselineConfig.frames"):
        BaselineConfig(frames=1)
    with pytest.raises(ValueError, match="BaselineConfig.max_noise_ut"):
        BaselineConfig(max_noise_ut=-1.0)
