"""The twin's terms for a printed skin: the press's image in the rigid base and the lattice's nodes. Off, they are
the plain kernel; on, they stay finite at zero depth, on a magnet and on a node, and read float32 inputs."""

import dataclasses

import numpy as np
import pytest

from tactile_manip.boards import load_board
from tactile_manip.boards.spec import TwinSpec
from tactile_manip.boards.write import board_toml
from tactile_manip.sim.twin import BoardTwin, Cells, board_magnets, magnet_motion, node_closeness, press_change_pad_ut
from tactile_manip.sim.twin_fit import PressLog, fit_twin

CELLS = Cells(period_mm=8.0, angle_deg=10.0, phase=(0.2, -0.3), sharpness=1.5, stiffness=0.3, depth=-0.2, tilt=0.4)


def skin_board(**terms):
    """The eFlesh board with a twin (rig origin (289, -100) mm, a quarter turn) and the given skin terms."""
    board = load_board("eflesh")
    twin = TwinSpec(rig_origin_mm=(289.0, -100.0), rig_turn_deg=90.0, contact_z_mm=145.0, press_gain=0.6,
                    press_exponent=1.3, kernel_depth_mm=9.0, lateral_scale=0.8, tilt_scale=1.0, **terms)
    return dataclasses.replace(board, name="cube-skin", twin=twin, path=None)


LATTICE = {"base_image": 0.4, "cell_period_mm": 8.0, "cell_angle_deg": 10.0, "cell_phase": (0.2, -0.3),
           "cell_sharpness": 1.5, "cell_stiffness": 0.3, "cell_depth": -0.2, "cell_tilt": 0.4}


def nodes_of(cells, rows=range(-2, 3)):
    """(K, 2) pad points of the lattice's nodes."""
    a = np.radians(cells.angle_deg)
    axes = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])  # rows: the lattice's axes in the pad
    return np.array([((i + cells.phase[0]) * axes[0] + (j + cells.phase[1]) * axes[1]) * cells.period_mm
                     for i in rows for j in rows])


def test_node_closeness_is_one_on_nodes_nothing_between_rows_and_periodic():
    nodes = nodes_of(CELLS)
    np.testing.assert_allclose(node_closeness(nodes, CELLS), 1.0, atol=1e-12)
    a = np.radians(CELLS.angle_deg)
    half_row = 0.5 * CELLS.period_mm * np.array([np.cos(a), np.sin(a)])
    np.testing.assert_allclose(node_closeness(nodes + half_row, CELLS), 0.0, atol=1e-12)
    pts = np.random.default_rng(0).uniform(-20, 20, (200, 2))
    g = node_closeness(pts, CELLS)
    assert np.all((g >= 0.0) & (g <= 1.0))
    np.testing.assert_allclose(node_closeness(pts + nodes[7] - nodes[0], CELLS), g, atol=1e-9)  # a lattice step
    np.testing.assert_allclose(node_closeness(pts.astype(np.float32), CELLS), g, atol=1e-5)


def test_terms_off_are_the_plain_kernel():
    board = skin_board()
    twin = BoardTwin(board)
    mags, chips = board_magnets(board), board.chip_positions_mm()
    rng = np.random.default_rng(1)
    xy, s = rng.uniform(-15, 15, (30, 2)), rng.uniform(0.1, 3.0, 30)
    plain = press_change_pad_ut(chips, mags, xy, s, kernel_depth_mm=9.0, lateral_scale=0.8, tilt_scale=1.0)
    idle = Cells(period_mm=8.0)  # a lattice whose nodes change nothing
    np.testing.assert_allclose(press_change_pad_ut(chips, mags, xy, s, kernel_depth_mm=9.0, lateral_scale=0.8,
                                                   tilt_scale=1.0, base_image=0.0, base_depth_mm=20.0, cells=idle),
                               plain, rtol=1e-12, atol=1e-9)
    assert twin.readings_at_pad_ut(xy, np.full(30, 2.0)).shape == (30, 5, 3)


def test_the_base_image_takes_out_motion_and_vanishes_for_a_magnet_on_the_base():
    centres = np.array([[0.0, 0.0, -2.0], [0.0, 0.0, -20.0]])  # under the press: near the surface, on the base
    xy, s = np.zeros((1, 2)), np.array([1.0])
    u, _ = magnet_motion(xy, s, centres, kernel_depth_mm=9.0, lateral_scale=1.0, tilt_scale=1.0)
    image = 9.0 + 2.0 * np.maximum(20.0 + centres[:, 2], 0.0)
    u_image, _ = magnet_motion(xy, s, centres, kernel_depth_mm=image[None], lateral_scale=1.0, tilt_scale=1.0)
    assert u_image[0, 0, 2] > u[0, 0, 2]  # the image's sink is shallower: the base holds the magnet back
    np.testing.assert_allclose(u_image[0, 1], u[0, 1])  # on the base the image is the press itself: no motion


def test_zero_depth_a_press_on_a_magnet_and_on_a_node_stay_finite():
    board = skin_board(**LATTICE)
    twin = BoardTwin(board)
    mags = board_magnets(board).centres_mm[:, :2]
    assert not twin.readings_at_pad_ut(mags, np.zeros(len(mags))).any()  # no approach: no change, terms or not
    on_magnet = twin.readings_at_pad_ut(mags, np.full(len(mags), 3.0))
    on_node = twin.readings_at_pad_ut(nodes_of(Cells.of(board.twin)), np.full(25, 3.0))
    assert np.isfinite(on_magnet).all() and np.isfinite(on_node).all()
    assert np.abs(on_magnet).max() > 10.0
    u, omega = magnet_motion(mags[:1], np.array([1.0]), board_magnets(board).centres_mm[:1], kernel_depth_mm=9.0,
                             lateral_scale=1.0, tilt_scale=1.0)
    np.testing.assert_allclose(u[0, 0, :2], 0.0, atol=1e-12)  # straight above a magnet: it only sinks
    np.testing.assert_allclose(omega[0, 0], 0.0, atol=1e-9)    # ... and does not turn


def test_float32_poses_read_as_float64_ones():
    twin = BoardTwin(skin_board(**LATTICE))
    stage = np.column_stack([np.linspace(276, 302, 20), np.linspace(-112, -88, 20), np.linspace(141, 145, 20)])
    np.testing.assert_allclose(twin.readings_ut(stage.astype(np.float32)), twin.readings_ut(stage), rtol=1e-4,
                               atol=0.05)


def test_a_board_with_skin_terms_reads_back_and_simulates_the_same(tmp_path):
    board = skin_board(**LATTICE)
    path = tmp_path / "cube.toml"
    path.write_text(board_toml(board))
    again = load_board(path)
    assert again.twin == board.twin
    stage = np.column_stack([np.full(5, 290.0), np.linspace(-110, -90, 5), np.full(5, 142.0)])
    np.testing.assert_allclose(BoardTwin(again).readings_ut(stage), BoardTwin(board).readings_ut(stage))
    assert not np.allclose(BoardTwin(skin_board()).readings_ut(stage), BoardTwin(board).readings_ut(stage))


@pytest.mark.parametrize("field, value", [("base_image", 1.5), ("cell_period_mm", -1.0), ("cell_sharpness", 0.0),
                                          ("cell_stiffness", float("nan"))])
def test_bad_skin_terms_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        skin_board(**{field: value})


def test_a_handful_of_presses_leaves_the_skin_terms_off():
    truth = BoardTwin(skin_board(**LATTICE))
    rng = np.random.default_rng(2)
    stage = np.column_stack([rng.uniform(274, 304, 25), rng.uniform(-115, -85, 25), rng.uniform(141, 145, 25)])
    log = PressLog(stage, truth.readings_ut(stage), np.zeros(25))
    fit = fit_twin(load_board("eflesh"), log, rest_ut=truth.rest_readings_ut(), max_evaluations=8)
    assert fit.stages["cells"]["note"].startswith("off") and fit.stages["base"]["note"].startswith("off")
    assert fit.board.twin.cell_period_mm == 0.0 and fit.board.twin.base_image == 0.0
