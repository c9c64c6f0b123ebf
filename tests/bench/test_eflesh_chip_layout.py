"""The chip layouts the eFlesh layout benchmark scores: the mirror image of the board reads what left-handed chips
at the file's places read of the mirrored discs, and turning two chips alone is neither (no data here)."""

from __future__ import annotations

import numpy as np

from benchmarks.eflesh_chip_layout import layouts, square_field_ut
from tactile_manip.boards import load_board
from tactile_manip.sim.twin import Magnets, board_magnets, discs_field_pad_ut


def _readings(board, centres_mm: np.ndarray) -> np.ndarray:
    magnets = Magnets(centres_mm=centres_mm, polarisation_t=np.full(len(centres_mm), 1.4),
                      size_mm=board_magnets(board).size_mm)
    field = discs_field_pad_ut(board.chip_positions_mm(), magnets, centres_mm[None])[0]
    return np.einsum("cji,cj->ci", board.chip_matrices(), field)  # pad field -> chip axes


def test_the_mirror_image_reads_as_left_handed_chips_do_and_two_turned_chips_do_not() -> None:
    board = load_board("eflesh")
    found = {name: b for name, (b, _) in layouts(board).items()}
    assert [round(float(np.linalg.det(m))) for m in found["left_handed"].chip_matrices()] == [-1] * 5
    assert [round(float(np.linalg.det(m))) for m in found["mirror_image"].chip_matrices()] == [1] * 5
    assert found["file"] is board
    rng = np.random.default_rng(0)
    centres = np.c_[rng.uniform(-14.0, 14.0, (4, 2)), np.full(4, -6.5)]
    mirrored = centres * [1.0, -1.0, 1.0]  # the discs seen in a mirror across the pad's x axis
    left = _readings(found["left_handed"], centres)
    np.testing.assert_allclose(_readings(found["mirror_image"], mirrored), left, rtol=1e-9, atol=1e-6)
    turned = _readings(found["right_down_half_turn"], mirrored)
    assert np.abs(turned - left).max() > 100.0  # uT: the file with two chips turned reads otherwise


def test_the_square_of_discs_is_centred_where_asked() -> None:
    board = load_board("eflesh")
    chips = np.array([[0.0, 0.0, -21.0]])
    centred = square_field_ut(np.array([0.0, 0.0, 0.3, -6.5, 20.0, 1.4]), chips, board_magnets(board).size_mm)
    np.testing.assert_allclose(centred[0, :2], 0.0, atol=1e-6)  # a chip under the square's centre: no in-plane field
    assert centred[0, 2] > 1000.0
