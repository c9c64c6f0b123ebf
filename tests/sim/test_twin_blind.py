"""The label-free twin fit's parts: the rest field places a known rigid layout of discs, and presses of the twin
itself lie on its bank both ways."""

import numpy as np

from tactile_manip.boards import load_board
from tactile_manip.sim import twin_blind
from tactile_manip.sim.twin import Magnets, board_magnets, discs_field_pad_ut


def test_the_rest_field_places_a_shifted_turned_layout_of_discs():
    board = load_board("eflesh")
    start = board_magnets(board)
    turn = np.radians(4.0)
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    xy = 1.05 * start.centres_mm[:, :2] @ rot.T + [1.5, -2.0]
    polarity = np.sign(start.polarisation_t)  # the file's: the fit keeps each disc's polarity
    true = Magnets(np.c_[xy, np.full(4, -7.5)], polarity * np.array([1.3, 1.25, 1.35, 1.2]), start.size_mm)
    readout = np.transpose(board.chip_matrices(), (0, 2, 1))
    rest = np.einsum("cij,cj->ci", readout, discs_field_pad_ut(board.chip_positions_mm(), true, true.centres_mm[None])[0])
    found, rms = twin_blind.fit_rest_magnets(board, rest, each_strength=True)
    assert rms < 1.0
    np.testing.assert_allclose(found.centres_mm, true.centres_mm, atol=0.05)
    np.testing.assert_allclose(found.polarisation_t, true.polarisation_t, atol=0.01)


def test_the_twins_own_presses_lie_on_its_bank_both_ways():
    board = load_board("eflesh")
    kernel = {"kernel_depth_mm": 11.0, "lateral_scale": 0.0, "tilt_scale": 1.0}
    change, where, strength = twin_blind.press_bank(board, board_magnets(board), kernel, 2.0)
    readout = np.transpose(board.chip_matrices(), (0, 2, 1))
    rng = np.random.default_rng(0)
    rows = rng.choice(len(change), 300, replace=False)
    readings = 1.7 * twin_blind._read(readout, change[rows])  # any scale: the chamfer compares directions
    forward, back = twin_blind.symmetric_chamfer(readings, change, where, strength, readout)
    assert forward < 1e-12 and back < 0.05
    other = twin_blind.symmetric_chamfer(readings[:, ::-1], change, where, strength, readout)  # chips swapped
    assert sum(other) > 10 * (forward + back)
