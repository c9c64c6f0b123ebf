"""Baseline (no-contact offset) of a magnetic tactile sensor: the mean of idle frames, refused when noisy.

A baseline is the per-channel mean of about a second of frames with nothing on the pad. A contact during
that second moves the field by tens to hundreds of microtesla, far above the chips' noise of a few uT, so a
channel whose standard deviation exceeds a threshold means the pad was touched (or the sensor is faulty)
and the baseline is refused. A contact held perfectly still is indistinguishable from an idle pad by this
test; take baselines with the pad free.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from tactile_manip.chips import ChipSettings
from tactile_manip.errors import CalibrationError
from tactile_manip.sensors.config import BaselineConfig

AXES = "xyz"


@dataclass(frozen=True, eq=False)
class Baseline:
    """A no-contact offset and how it was measured.

    Attributes:
        offset_ut: (R, C, 3) float32 mean raw field, uT (the reading's shape); readings report ``raw - offset_ut``.
        noise_ut: (R, C, 3) float32 per-channel standard deviation over the frames, uT (zeros when set by hand).
        frames: number of frames averaged (0 when set by hand).
        t_host_s: host monotonic time when it was taken, s.
        temperature_c: (R, C) mean chip temperatures over the frames, degC, or None when they sent none.
    """

    offset_ut: np.ndarray
    noise_ut: np.ndarray
    frames: int
    t_host_s: float
    temperature_c: np.ndarray | None = None


def noise_thresholds_ut(config: BaselineConfig, chip: ChipSettings) -> np.ndarray:
    """Per-axis std threshold (3,) in uT: ``max_noise_ut`` if set, else ``noise_factor`` x the rated noise."""
    if config.max_noise_ut is not None:
        return np.full(3, config.max_noise_ut)
    rated = np.array([chip.noise_xy_ut, chip.noise_xy_ut, chip.noise_z_ut])
    # never below two LSB: a noise-free chip still toggles its last bit
    floor = 2.0 * np.array([chip.lsb_xy_ut, chip.lsb_xy_ut, chip.lsb_z_ut])
    return np.maximum(config.noise_factor * rated, floor)


def baseline_from_frames(raw_ut: np.ndarray, saturated: np.ndarray, thresholds_ut: np.ndarray, *,
                         source: str = "sensor") -> Baseline:
    """Average idle frames into a :class:`Baseline`, or refuse them.

    Args:
        raw_ut: (N, R, C, 3) raw fields, uT, N >= 2 ((N, 4, 4, 3) for the SuperMag board).
        saturated: (N, R, C, 3) bool, channels at the rail.
        thresholds_ut: (3,) largest accepted per-channel std for the x, y, z axes, uT.
        source: names the sensor in messages.

    Raises:
        CalibrationError: a channel saturated, or a channel's std exceeds its axis threshold; the message
            names the worst channel, its noise, the threshold and what to do.
    """
    raw = np.asarray(raw_ut, dtype=np.float64)
    if raw.ndim != 4 or raw.shape[-1] != 3 or raw.shape[0] < 2:
        raise ValueError(f"raw_ut: expected shape (N >= 2, rows, cols, 3), got {raw.shape}")
    if np.asarray(saturated).any():
        r, c, a = np.argwhere(np.asarray(saturated).any(axis=0))[0]
        raise CalibrationError(f"baseline refused on {source}: chip ({r}, {c}) axis {AXES[a]} is saturated; "
                               "move magnets or metal away from the pad and call rezero()")
    std = raw.std(axis=0, ddof=1)
    excess = std / np.asarray(thresholds_ut, dtype=np.float64)
    if (excess > 1.0).any():
        r, c, a = np.unravel_index(int(np.argmax(excess)), excess.shape)
        noisy = int((excess > 1.0).sum())
        per_axis = ", ".join(f"{AXES[i]} {std[..., i].max():.1f}" for i in range(3))
        limits = ", ".join(f"{AXES[i]} {thresholds_ut[i]:.1f}" for i in range(3))
        raise CalibrationError(
            f"baseline refused on {source}: noise {std[r, c, a]:.1f} uT on chip ({r}, {c}) axis {AXES[a]} exceeds "
            f"the {thresholds_ut[a]:.1f} uT threshold ({noisy} of {std.size} channels over; max std per axis: "
            f"{per_axis} uT; "
            f"thresholds: {limits} uT). Is something touching the pad? Release it and call rezero(); if this "
            "sensor is simply noisier, raise BaselineConfig.max_noise_ut")
    return Baseline(offset_ut=raw.mean(axis=0).astype(np.float32), noise_ut=std.astype(np.float32),
                    frames=raw.shape[0], t_host_s=time.monotonic())
