"""The chip layouts the eFlesh layout benchmark scores: the mirror image of the former board file reads what
left-handed chips at the file's places read of the mirrored discs, those chips' axes negated over discs polarised -z
read the same (right-handed: the chips upside down; the layout the board file holds), and turning two chips alone is
neither (no data here)."""

from __future__ import annotations

import numpy as np

from benchmarks.eflesh_chip_layout import layouts, square_field_ut
from tactile_manip.boards import load_board
from tactile_manip.sim.board_press import press
from tactile_manip.sim.board_skin import BoardSkin
from tactile_manip.sim.twin import Magnets, board_magnets, discs_field_pad_ut


def _readings(board, centres_mm: np.ndarray, polarisation_t: float = 1.4) -> np.ndarray:
    magnets = Magnets(centres_mm=centres_mm, polarisation_t=np.full(len(centres_mm), polarisation_t),
                      size_mm=board_magnets(board).size_mm)
    field = discs_field_pad_ut(board.chip_positions_mm(), magnets, centres_mm[None])[0]
    return np.einsum("cji,cj->ci", board.chip_matrices(), field)  # pad field -> chip axes


def test_the_mirror_image_reads_as_left_handed_chips_do_and_two_turned_chips_do_not() -> None:
    board = load_board("eflesh")
    found = {name: b for name, (b, _) in layouts(board).items()}
    assert [round(float(np.linalg.det(m))) for m in found["left_handed"].chip_matrices()] == [-1] * 5
    assert [round(float(np.linalg.det(m))) for m in found["mirror_image"].chip_matrices()] == [1] * 5
    assert [c.rotation_deg for c in found["former_file"].chips] == [90.0, 90.0, 180.0, -90.0, 0.0]
    assert [m.polarisation_t for m in found["former_file"].body.magnets] == [(0.0, 0.0, 1.45)] * 4
    rng = np.random.default_rng(0)
    centres = np.c_[rng.uniform(-14.0, 14.0, (4, 2)), np.full(4, -6.5)]
    mirrored = centres * [1.0, -1.0, 1.0]  # the discs seen in a mirror across the pad's x axis
    left = _readings(found["left_handed"], centres)
    np.testing.assert_allclose(_readings(found["mirror_image"], mirrored), left, rtol=1e-9, atol=1e-6)
    turned = _readings(found["right_down_half_turn"], mirrored)
    assert np.abs(turned - left).max() > 100.0  # uT: the file with two chips turned reads otherwise


def test_upside_down_chips_over_reversed_discs_read_as_the_left_handed_chips_do() -> None:
    board = load_board("eflesh")
    found = {name: b for name, (b, _) in layouts(board).items()}
    upside_down, left = found["upside_down"], found["left_handed"]
    assert [round(float(np.linalg.det(m))) for m in upside_down.chip_matrices()] == [1] * 5
    np.testing.assert_array_equal(upside_down.chip_matrices(), -left.chip_matrices())
    np.testing.assert_array_equal(upside_down.chip_positions_mm(), board.chip_positions_mm())
    assert [m.polarisation_t for m in upside_down.body.magnets] == [(0.0, 0.0, -1.45)] * 4
    assert [m.polarisation_t for m in left.body.magnets] == [(0.0, 0.0, 1.45)] * 4
    # the board file holds this layout: its chips' axes and its discs are these
    assert [c.axes for c in upside_down.chips] == [c.axes for c in board.chips]
    assert upside_down.body == board.body and upside_down.fingerprint == board.fingerprint
    rng = np.random.default_rng(1)
    centres = np.c_[rng.uniform(-14.0, 14.0, (4, 2)), np.full(4, -6.5)]
    np.testing.assert_allclose(_readings(upside_down, centres, -1.4), _readings(left, centres), rtol=1e-12,
                               atol=1e-9)
    assert np.abs(_readings(upside_down, centres) - _readings(left, centres)).max() > 100.0  # discs as the file's
    # the full simulator (a contact solve, the layer's displacement, the discs moved and turned) reads -z too
    skins = [BoardSkin(b, pixel_mm=1.0) for b in (upside_down, left)]
    np.testing.assert_allclose(skins[0].baseline_ut(), skins[1].baseline_ut(), rtol=1e-12, atol=1e-9)
    presses = [press(skin, tip="sphere", tip_diameter_mm=6.0, x_mm=2.0, y_mm=-3.0, force_n=3.0).reading_ut
               for skin in skins]
    assert np.abs(presses[1]).max() > 10.0
    np.testing.assert_allclose(presses[0], presses[1], rtol=1e-9, atol=1e-9)


def test_the_square_of_discs_is_centred_where_asked() -> None:
    board = load_board("eflesh")
    chips = np.array([[0.0, 0.0, -21.0]])
    centred = square_field_ut(np.array([0.0, 0.0, 0.3, -6.5, 20.0, 1.4]), chips, board_magnets(board).size_mm)
    np.testing.assert_allclose(centred[0, :2], 0.0, atol=1e-6)  # a chip under the square's centre: no in-plane field
    assert centred[0, 2] > 1000.0
