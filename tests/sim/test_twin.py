"""The board twin: Boussinesq's closed form, the fitted board file's round trip, and a fit that finds a known twin
again from its simulated log."""

import dataclasses

import numpy as np
import pytest

from tactile_manip.boards import load_board
from tactile_manip.boards.spec import ReadoutSpec, TwinSpec
from tactile_manip.boards.write import board_toml
from tactile_manip.errors import ConfigError
from tactile_manip.sim.twin import BoardTwin, kernel_displacement, rig_to_pad
from tactile_manip.sim.twin_fit import PressLog, chip_orders, explained_variance, fit_twin, with_chip_order

TURNED = ((0.0, 1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0))


def known_board(name="cube-twin"):
    """The eFlesh board with a twin of known numbers: rig origin (289, -100) mm, a quarter turn, chip 1 read
    through a turned readout."""
    board = load_board("eflesh")
    readout = [ReadoutSpec(matrix=tuple(map(tuple, c.matrix().T))) for c in board.chips]
    readout[0] = ReadoutSpec(matrix=TURNED, offset_ut=(30.0, -20.0, 50.0))
    twin = TwinSpec(rig_origin_mm=(289.0, -100.0), rig_turn_deg=90.0, contact_z_mm=145.0, press_gain=0.6,
                    press_exponent=1.3, kernel_depth_mm=9.0, lateral_scale=0.8, tilt_scale=1.0,
                    readout=tuple(readout))
    return dataclasses.replace(board, name=name, twin=twin, path=None)


def grid_log(rng, n=600):
    stage = np.column_stack([rng.uniform(274, 304, n), rng.uniform(-115, -85, n), rng.uniform(141, 145, n)])
    return stage


def test_boussinesq_closed_form():
    s, h = 0.5, 6.0
    u = kernel_displacement(np.array(0.0), np.array(0.0), np.array(h), np.array(s), 1.0)
    np.testing.assert_allclose(u, [0.0, 0.0, -2 * s / h])  # straight below: u_z = -2 s / h, no lateral motion
    side = kernel_displacement(np.array(3.0), np.array(4.0), np.array(h), np.array(s), 1.0)
    big_r = np.hypot(5.0, h)
    np.testing.assert_allclose(side[2], -s * (1 + h * h / big_r ** 2) / big_r)
    np.testing.assert_allclose(np.hypot(*side[:2]), s * 5.0 * h / big_r ** 3)
    assert side[0] > 0 and side[1] > 0  # incompressible: material under the load moves away from it


def test_rig_frame_turns_mirrors_and_clips_the_approach():
    stage = np.array([[290.0, -100.0, 146.0], [289.0, -99.0, 144.0]])
    xy, depth = rig_to_pad(stage, origin_mm=(289.0, -100.0), turn_deg=90.0, contact_z_mm=145.0, depth_per_z=-1.0)
    np.testing.assert_allclose(xy, [[0.0, 1.0], [-1.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(depth, [0.0, 1.0])
    xy, _ = rig_to_pad(stage, origin_mm=(289.0, -100.0), turn_deg=0.0, contact_z_mm=145.0, depth_per_z=-1.0,
                       mirror=True)
    np.testing.assert_allclose(xy, [[1.0, 0.0], [0.0, -1.0]], atol=1e-12)


def test_fitted_board_file_reads_back_and_simulates_the_same(tmp_path):
    board = dataclasses.replace(known_board(), fit={"rows": {"fitted": 600}, "files": {"sensor.csv": "abc"}})
    path = tmp_path / "cube.toml"
    path.write_text(board_toml(board))
    again = load_board(path)
    assert again.twin == board.twin and again.body == board.body and again.fit == board.fit
    assert again.fingerprint == load_board("eflesh").fingerprint  # the chips are the file's: readings mean the same
    stage = grid_log(np.random.default_rng(0), 50)
    np.testing.assert_allclose(BoardTwin(again).readings_ut(stage), BoardTwin(board).readings_ut(stage), rtol=1e-5,
                               atol=1e-3)


def test_a_probe_above_the_pad_changes_nothing_and_raw_adds_the_rest_field():
    twin = BoardTwin(known_board())
    above = np.array([[289.0, -100.0, 146.0], [280.0, -90.0, 150.0]])
    assert not twin.readings_ut(above).any()
    np.testing.assert_allclose(twin.readings_ut(above, raw=True), np.broadcast_to(twin.rest_readings_ut(), (2, 5, 3)))
    deep = twin.readings_ut(np.array([[289.0, -100.0, 142.0]]))
    assert np.abs(deep).max() > 50.0  # a 3 mm press moves the field by tens of uT at least


def test_presses_at_pad_points_are_the_logged_poses_through_the_rig_frame():
    twin = BoardTwin(known_board())
    stage = grid_log(np.random.default_rng(1), 40)
    xy, approach = twin.pad_poses(stage)
    np.testing.assert_allclose(twin.readings_at_pad_ut(xy, approach), twin.readings_ut(stage), rtol=1e-12)
    assert not twin.readings_at_pad_ut(np.zeros((1, 2)), np.array([-1.0])).any()  # above the pad: no press


def test_a_board_without_twin_is_refused():
    with pytest.raises(ConfigError, match="fit-board"):
        BoardTwin(load_board("eflesh"))


@pytest.mark.slow
def test_fit_finds_a_known_twin_again():
    board = known_board()
    truth = BoardTwin(board)
    rng = np.random.default_rng(0)
    stage = grid_log(rng, 500)
    readings = truth.readings_ut(stage) + rng.normal(0.0, 2.0, (len(stage), 5, 3))
    fit_part, test_part = slice(0, 400), slice(400, None)
    log = PressLog(stage[fit_part], readings[fit_part], np.zeros(400))
    fit = fit_twin(load_board("eflesh"), log, rest_ut=truth.rest_readings_ut(), max_evaluations=40)
    assert fit.stages["readout"]["ev"] > 0.97
    pred = BoardTwin(fit.board).readings_ut(stage[test_part])
    ev, per_channel = explained_variance(readings[test_part], pred)
    assert ev > 0.95 and min(per_channel) > 0.8


def test_the_chip_orders_searched_are_the_crosss_placements_up_to_its_symmetries():
    board = load_board("eflesh")
    orders = chip_orders(board.chip_positions_mm())
    assert len(orders) == 120 // 8 and orders[0] == (0, 1, 2, 3, 4)
    # a quarter turn of the pad (left -> down, right -> up, up -> left, down -> right) or a mirror image (left <->
    # right) gives a placement that is the same board turned: never listed beside the one it came from
    for symmetry in ({0: 0, 1: 4, 2: 3, 3: 1, 4: 2}, {0: 0, 1: 2, 2: 1, 3: 3, 4: 4}):
        for order in orders:
            image = tuple(symmetry[k] for k in order)
            assert image == order or image not in orders
    swapped = with_chip_order(board, (0, 2, 1, 3, 4))
    assert swapped.chips[1].position_mm == board.chips[2].position_mm and swapped.chips[1].cell == board.chips[2].cell
    assert swapped.chips[1].rotation_deg == board.chips[1].rotation_deg
    with pytest.raises(ValueError, match="at most 6 chips"):
        chip_orders(load_board("supermag-4x4").chip_positions_mm())
