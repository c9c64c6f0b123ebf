"""The sensor pair, the dataset and the simulated sensor on any described board, not only the SuperMag pad."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from tactile_manip.boards import load_board
from tactile_manip.errors import ConfigError
from tactile_manip.sim.dataset import DatasetConfig, ObjectSpec, generate, recorded_sim_params
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.params import for_board
from tactile_manip.sim.shapes import make_indenter

SIM = Path(__file__).resolve().parents[2] / "tactile_manip" / "sim"
CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)


@pytest.mark.parametrize("name", ["eflesh", "anyskin-5"])
def test_a_press_on_a_five_chip_board_fills_its_cross_and_leaves_the_corners(name):
    pair = SensorPair(board=load_board(name))
    rod = make_indenter("cylinder", size_mm=4.0)
    s = pair.press(rod, IndenterPose(x_mm=1.0, yaw_rad=0.3), 8.0, np.random.default_rng(0), render_depth=False)
    assert s.field_ut.shape == s.field_change_ut.shape == s.saturated.shape == (3, 3, 3)
    assert not s.field_ut[~CROSS].any() and not s.field_change_ut[~CROSS].any()
    noise = max(pair.params.chip.noise_xy_ut, pair.params.chip.noise_z_ut)
    assert np.abs(s.field_change_ut[CROSS]).max() > 5 * noise      # the press reads well above the chips' noise
    np.testing.assert_allclose(s.field_clean_ut, pair.expected_reading_ut(rod, s.pose, 8.0), atol=1e-3)
    assert pair.params.chip.lsb_xy_ut == load_board(name).chip.lsb_xy_ut  # the chip model is the board file's


def test_the_supermag_numbers_come_from_its_board_file():
    board = load_board("supermag-4x4")
    p = for_board(board)
    assert (p.layer.skin_modulus_kpa, p.magnet.remanence_t, p.magnet.chip_gap_mm) == (
        board.layer.modulus_kpa, board.body.remanence_t, board.layer.gap_mm)
    assert (p.chip.lsb_xy_ut, p.chip.lsb_z_ut, p.chip.rate_hz) == (board.chip.lsb_xy_ut, board.chip.lsb_z_ut,
                                                                   board.chip.rate_hz)
    pair = SensorPair(board=board)
    np.testing.assert_array_equal(pair.skin.chips_mm[:, :2], [c.position_mm for c in board.chips])


def test_no_reading_grid_is_hard_coded_in_the_simulator():
    # a (4, 4, 3) reading, a 4x4 grid constant or a reshape to it; a line naming the SuperMag board may quote it
    pattern = re.compile(r"\(4, 4, 3\)|\bGRID\b|reshape\(4, 4|\(GRID, GRID")
    hits = [f"{path.name}:{i}" for path in sorted(SIM.glob("*.py"))
            for i, line in enumerate(path.read_text().splitlines(), 1)
            if pattern.search(line) and "supermag" not in line.lower()]
    assert hits == []


def test_a_dataset_of_another_board_has_its_grid_and_names_it():
    cfg = DatasetConfig(board="eflesh", objects=[ObjectSpec("cylinder", count=3, kwargs={"size_mm": 6.0})],
                        images=False)
    data = generate(cfg, workers=1)
    assert data.readings.shape == (3, 3, 3, 3) and data.provenance["layout"] == "eflesh"
    assert not data.readings[:, ~CROSS].any() and data.targets[:, -1].all()   # every press touched the cube
    with pytest.raises(ConfigError, match="generic:4 has no geometry"):
        DatasetConfig(board="generic:4", objects=[ObjectSpec("cylinder", count=1)])


def test_a_dataset_made_before_board_files_keeps_its_recorded_parameters():
    old = {"seed": 0, "objects": [{"name": "cylinder", "count": 1}],
           "sim": {"layer": {"size_mm": 20.0, "thickness_mm": 2.5, "skin_modulus_kpa": 210.0},
                   "chip": {"pitch_mm": 5.0, "noise_xy_ut": 3.0}}}
    params = recorded_sim_params(old)
    assert (params.layer.skin_modulus_kpa, params.chip.noise_xy_ut, params.chip.lsb_z_ut) == (210.0, 3.0, 0.323)


def test_a_board_without_magnets_cannot_be_simulated():
    with pytest.raises(ConfigError, match="no geometry and cannot be simulated"):
        SensorPair(board=load_board("generic:5"))
