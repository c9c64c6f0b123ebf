"""Tests of the chip array model (16 chips of the SuperMag board here): positions, quantisation, saturation, noise, rotations, Earth, drift."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tactile_manip.boards import load_board
from tactile_manip.sim.chip import ChipArray, Measurement, chip_positions_mm
from tactile_manip.sim.magnetics import cuboid_field_t
from tactile_manip.sim.params import ChipParams, for_board

SUPERMAG = load_board("supermag-4x4")
NOMINAL = for_board(SUPERMAG)
QUIET = dataclasses.replace(NOMINAL.chip, noise_xy_ut=0.0, noise_z_ut=0.0, drift_ut=0.0)


def _array(params: ChipParams = QUIET, seed: int = 0) -> ChipArray:
    return ChipArray.create(params, np.random.default_rng(seed), n_chips=16)


def _ideal(params: ChipParams = QUIET) -> ChipArray:
    """No Earth field, no rotation: readings are the input field."""
    return ChipArray(params=params, earth_ut=np.zeros(3), rotations=np.broadcast_to(np.eye(3), (16, 3, 3)))


def test_positions_layout():
    pos = chip_positions_mm(SUPERMAG, thickness_mm=2.5, gap_mm=1.0).reshape(4, 4, 3)  # chip i at cell (i // 4, i % 4)
    assert pos.shape == (4, 4, 3)
    np.testing.assert_allclose(pos[0, 0], [-7.5, 7.5, -3.5])  # row 0 is +y, col 0 is -x
    np.testing.assert_allclose(pos[3, 3], [7.5, -7.5, -3.5])
    np.testing.assert_allclose(pos[1, 2], [2.5, 2.5, -3.5])
    assert np.all(np.diff(pos[..., 0], axis=1) == 5.0) and np.all(np.diff(pos[..., 1], axis=0) == -5.0)


def test_zero_noise_measurement_is_rounded_expected_value():
    chips = _array(dataclasses.replace(QUIET, rotation_deg=2.0))
    field = np.random.default_rng(1).normal(0.0, 2000.0, (16, 3))
    m = chips.measure(field, np.random.default_rng(2))
    lsb = np.array([0.2, 0.2, 0.323])
    assert isinstance(m, Measurement)
    assert m.counts.dtype == np.int16 and m.raw_ut.dtype == np.float32 and m.saturated.dtype == bool
    np.testing.assert_array_equal(m.counts, np.rint(chips.expected_ut(field) / lsb))
    np.testing.assert_allclose(m.raw_ut, m.counts * lsb, rtol=1e-6)
    np.testing.assert_allclose(chips.counts_to_ut(m.counts), m.raw_ut)
    assert not m.saturated.any()


def test_quantisation_step_is_lsb_per_axis():
    chips = _ideal()
    steps = []
    for ramp_ut in np.linspace(0.0, 3.0, 301):
        m = chips.measure(np.full((16, 3), ramp_ut), np.random.default_rng(0))
        steps.append(m.raw_ut[0])
    values = np.array(steps, dtype=np.float64)
    for axis, lsb in enumerate([0.2, 0.2, 0.323]):
        np.testing.assert_allclose(np.diff(np.unique(values[:, axis])), lsb, rtol=1e-5)


def test_saturation_clips_and_flags():
    chips = _ideal(dataclasses.replace(QUIET, saturation_counts=1000))
    field = np.zeros((16, 3))
    field[0] = [1e4, -1e4, 100.0]
    field[9, 2] = 1000 * 0.323
    m = chips.measure(field, np.random.default_rng(0))
    np.testing.assert_array_equal(m.counts[0], [1000, -1000, round(100.0 / 0.323)])
    assert m.saturated[0, 0] and m.saturated[0, 1] and not m.saturated[0, 2]
    assert m.saturated[9, 2]  # exactly at the rail counts as saturated
    assert m.saturated.sum() == 3
    full = _ideal().measure(np.full((16, 3), -1e6), np.random.default_rng(0))
    assert np.all(full.counts == -32767) and full.saturated.all()


def test_noise_std_matches_params():
    params = dataclasses.replace(QUIET, noise_xy_ut=5.0, noise_z_ut=8.0)
    chips, rng = _ideal(params), np.random.default_rng(3)
    frames = np.stack([chips.measure(np.zeros((16, 3)), rng).raw_ut for _ in range(400)])
    std = frames.reshape(-1, 3).std(axis=0)
    np.testing.assert_allclose(std, [5.0, 5.0, 8.0], rtol=0.03)


def test_rotation_zero_gives_identity():
    np.testing.assert_array_equal(_array().rotations, np.broadcast_to(np.eye(3), (16, 3, 3)))


def test_rotations_are_proper_with_rms_angle():
    params = dataclasses.replace(QUIET, rotation_deg=3.0)
    rng = np.random.default_rng(4)
    rots = np.concatenate([ChipArray.create(params, rng, n_chips=16).rotations for _ in range(200)])
    np.testing.assert_allclose(rots @ np.swapaxes(rots, -1, -2), np.broadcast_to(np.eye(3), rots.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rots), 1.0, atol=1e-12)
    cos = np.clip((np.trace(rots, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    rms_deg = np.rad2deg(np.sqrt(np.mean(np.arccos(cos) ** 2)))
    assert rms_deg == pytest.approx(3.0, rel=0.05)


def test_rotation_maps_pad_field_into_chip_axes():
    chips = _array(dataclasses.replace(QUIET, rotation_deg=5.0), seed=5)
    field = np.random.default_rng(6).normal(0.0, 500.0, (16, 3))
    got = chips.expected_ut(field)
    total = field + chips.earth_ut
    np.testing.assert_allclose(np.linalg.norm(got, axis=-1), np.linalg.norm(total, axis=-1), rtol=1e-12)
    np.testing.assert_allclose(got[6], chips.rotations[6].T @ total[6], rtol=1e-12)


def test_earth_field_magnitude_and_random_direction():
    params = dataclasses.replace(QUIET, earth_field_ut=42.0)
    a, b = _array(params, seed=0), _array(params, seed=1)
    assert np.linalg.norm(a.earth_ut) == pytest.approx(42.0)
    assert np.linalg.norm(b.earth_ut) == pytest.approx(42.0)
    assert not np.allclose(a.earth_ut, b.earth_ut)
    np.testing.assert_allclose(_ideal().expected_ut(np.ones((16, 3))), 1.0)
    np.testing.assert_allclose(a.expected_ut(np.zeros((16, 3))), np.broadcast_to(a.earth_ut, (16, 3)))


def test_drift_std_and_use():
    chips, rng = _ideal(dataclasses.replace(QUIET, drift_ut=5.0)), np.random.default_rng(7)
    drifts = np.stack([chips.draw_drift(rng) for _ in range(300)])
    assert drifts.shape == (300, 16, 3)
    assert drifts.std() == pytest.approx(5.0, rel=0.03) and abs(drifts.mean()) < 0.1
    m = chips.measure(np.zeros((16, 3)), rng, drift_ut=drifts[0])
    np.testing.assert_array_equal(m.counts, np.rint(drifts[0] / np.array([0.2, 0.2, 0.323])))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_raises(bad):
    field = np.zeros((16, 3))
    field[6, 0] = bad
    with pytest.raises(ValueError, match="field_ut"):
        _array().measure(field, np.random.default_rng(0))
    with pytest.raises(ValueError, match="field_ut"):
        _array().expected_ut(field)


def test_bad_shapes_and_params_raise():
    with pytest.raises(ValueError, match="field_ut"):
        _array().measure(np.zeros(48), np.random.default_rng(0))
    with pytest.raises(ValueError, match="drift_ut"):
        _array().measure(np.zeros((16, 3)), np.random.default_rng(0), drift_ut=np.zeros((4, 4, 3)))
    with pytest.raises(ValueError, match="saturation_counts"):
        _array(dataclasses.replace(QUIET, saturation_counts=40000))
    with pytest.raises(ValueError, match="gap_mm"):
        chip_positions_mm(SUPERMAG, thickness_mm=2.5, gap_mm=-1.0)


def test_float32_and_float64_input_agree():
    chips = _array(dataclasses.replace(NOMINAL.chip, rotation_deg=1.0))
    field32 = np.random.default_rng(8).normal(0.0, 3000.0, (16, 3)).astype(np.float32)
    m32 = chips.measure(field32, np.random.default_rng(9), drift_ut=np.ones((16, 3), np.float32))
    m64 = chips.measure(field32.astype(np.float64), np.random.default_rng(9), drift_ut=np.ones((16, 3)))
    np.testing.assert_array_equal(m32.counts, m64.counts)
    np.testing.assert_array_equal(m32.raw_ut, m64.raw_ut)


def test_default_baseline_is_inside_mlx90393_range():
    magnet, layer, chip = NOMINAL.magnet, SUPERMAG.layer, NOMINAL.chip
    pos = chip_positions_mm(SUPERMAG, thickness_mm=layer.thickness_mm, gap_mm=magnet.chip_gap_mm)
    field_t = cuboid_field_t(pos, size_mm=(*layer.size_mm, layer.thickness_mm),
                             centre_mm=(0.0, 0.0, -layer.thickness_mm / 2),
                             polarisation_t=(0.0, 0.0, magnet.remanence_t))
    worst_ut = np.abs(field_t * 1e6).max(axis=0) + chip.earth_field_ut  # Earth in the worst direction
    rail_ut = chip.saturation_counts * np.array([chip.lsb_xy_ut, chip.lsb_xy_ut, chip.lsb_z_ut])
    assert np.all(worst_ut < rail_ut)
    chips = ChipArray.create(chip, np.random.default_rng(0), n_chips=16)
    drift_ut = chips.draw_drift(np.random.default_rng(2))
    m = chips.measure(field_t * 1e6, np.random.default_rng(1), drift_ut=drift_ut)
    assert not m.saturated.any()
