"""The core chip spec (tactile_manip.chips): one set of MLX90393 figures that the simulator, the board files, the
drivers and the estimators read, and the drivers accept the simulator's ChipParams as well."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tactile_manip.boards import ChipModelSpec as BoardChipModelSpec
from tactile_manip.boards import load_board
from tactile_manip.chips import MLX90393, ChipModelSpec, as_chip_spec, full_scale_ut
from tactile_manip.config import from_dict
from tactile_manip.perception.reconstruct import READING_LIMIT_UT
from tactile_manip.sensors.baseline import noise_thresholds_ut
from tactile_manip.sensors.config import BaselineConfig, SerialSensorConfig
from tactile_manip.wire.protocol import CountScale
from tactile_manip.wire import make_decoder
from tactile_manip.sim.params import ChipParams, for_board

SHARED = ("lsb_xy_ut", "lsb_z_ut", "saturation_counts", "rate_hz", "noise_xy_ut", "noise_z_ut")


def test_the_board_files_chip_table_is_the_core_spec():
    assert BoardChipModelSpec is ChipModelSpec
    assert load_board("supermag-4x4").chip == MLX90393


def test_the_simulator_takes_the_boards_figures():
    assert all(getattr(ChipParams(), n) is None for n in SHARED)   # the board's, until filled in
    sim = for_board(load_board("supermag-4x4")).chip
    assert {n: getattr(sim, n) for n in SHARED} == {n: getattr(MLX90393, n) for n in SHARED}
    assert sim.spec() == MLX90393


def test_full_scale_is_the_rail_times_the_lsb():
    np.testing.assert_allclose(full_scale_ut(MLX90393), [32767 * 0.200, 32767 * 0.200, 32767 * 0.323])
    np.testing.assert_array_equal(full_scale_ut(for_board(load_board("supermag-4x4")).chip), full_scale_ut(MLX90393))
    assert MLX90393.full_scale_ut == tuple(full_scale_ut(MLX90393))
    np.testing.assert_array_equal(READING_LIMIT_UT, full_scale_ut(MLX90393))


def test_as_chip_spec_keeps_a_spec_and_converts_chip_params():
    assert as_chip_spec(MLX90393) is MLX90393
    drawn = dataclasses.replace(for_board(load_board("supermag-4x4")).chip, noise_xy_ut=7.0, noise_z_ut=9.0,
                                rate_hz=100.0, earth_field_ut=30.0)
    assert as_chip_spec(drawn) == dataclasses.replace(MLX90393, noise_xy_ut=7.0, noise_z_ut=9.0, rate_hz=100.0)


@pytest.mark.parametrize("changes, message", [
    ({"lsb_xy_ut": -0.2}, "chip.lsb_xy_ut must be > 0.0"),
    ({"noise_z_ut": float("nan")}, "chip.noise_z_ut must be a finite number"),
    ({"rate_hz": True}, "chip.rate_hz must be a finite number"),
    ({"saturation_counts": 0}, "chip.saturation_counts must be an integer from 1"),
])
def test_a_bad_figure_is_refused_by_name(changes, message):
    with pytest.raises(ValueError, match=message):
        ChipModelSpec(**changes)


def test_drivers_accept_the_core_spec_or_chip_params():
    spec, sim = ChipModelSpec(noise_xy_ut=3.0, lsb_z_ut=0.5), dataclasses.replace(for_board(load_board("supermag-4x4")).chip, noise_xy_ut=3.0, lsb_z_ut=0.5)
    np.testing.assert_array_equal(noise_thresholds_ut(BaselineConfig(), spec),
                                  noise_thresholds_ut(BaselineConfig(), sim))
    np.testing.assert_array_equal(CountScale.from_chip(spec).lsb_ut, CountScale.from_chip(sim).lsb_ut)
    for name, n in (("supermag", 16), ("anyskin", 5)):
        assert make_decoder(name, n_chips=n, chip=sim).chip is sim
        assert make_decoder(name, n_chips=n, chip=spec).chip is spec


def test_a_serial_config_holds_the_core_spec():
    given_sim = SerialSensorConfig(port="/dev/null", chip=dataclasses.replace(for_board(load_board("supermag-4x4")).chip,
                                                                              noise_xy_ut=3.0))
    assert given_sim.chip == ChipModelSpec(noise_xy_ut=3.0)
    loaded = from_dict(SerialSensorConfig, {"port": "/dev/null", "chip": {"noise_xy_ut": 3.0, "rate_hz": 100.0}})
    assert loaded.chip == ChipModelSpec(noise_xy_ut=3.0, rate_hz=100.0)
