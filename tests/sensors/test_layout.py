"""Boards as reading layouts: chip order, positions and rotations onto reading cells (docs/design.md, Conventions)."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_manip.boards import Board, ChipSpec, load_board
from tactile_manip.boards.spec import ChipGridSpec
from tactile_manip.sim.chip import chip_positions_mm

SUPERMAG_4X4 = load_board("supermag-4x4")
ANYSKIN_5 = load_board("anyskin-5")


def test_supermag_4x4_is_the_identity_at_the_simulators_chip_positions():
    rng = np.random.default_rng(0)
    chips = rng.normal(0, 300, (16, 3)).astype(np.float32)
    reading = SUPERMAG_4X4.reading_from_chips(chips)
    np.testing.assert_array_equal(reading, chips.reshape(4, 4, 3))
    assert np.shares_memory(reading, chips)                      # a reshape: no work on the default board
    sim = chip_positions_mm(SUPERMAG_4X4, thickness_mm=2.5, gap_mm=0.5)[:, :2].reshape(4, 4, 2)
    np.testing.assert_allclose(SUPERMAG_4X4.positions_mm(), sim)  # row 0 at +y, col 0 at -x
    assert SUPERMAG_4X4.positions_mm()[0, 0].tolist() == [-7.5, 7.5] and SUPERMAG_4X4.mask.all()


def test_anyskin_cross_fills_five_cells_in_pad_axes_and_masks_the_corners():
    chips = np.array([[1, 0, 10], [1, 0, 11], [1, 0, 12], [1, 0, 13], [1, 0, 14]], np.float32)  # +x in chip axes
    reading = ANYSKIN_5.reading_from_chips(chips)
    assert reading.shape == ANYSKIN_5.shape == (3, 3, 3)
    expected_mask = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)
    np.testing.assert_array_equal(ANYSKIN_5.mask, expected_mask)
    assert not reading[~expected_mask].any()
    # chip order centre, left, right, up, down; chip +x turned by 90, 90, 180, -90, 0 degrees
    cells = {(1, 1): ([0, 1], 10), (1, 0): ([0, 1], 11), (1, 2): ([-1, 0], 12), (0, 1): ([0, -1], 13),
             (2, 1): ([1, 0], 14)}
    for (r, c), (xy, z) in cells.items():
        np.testing.assert_allclose(reading[r, c], [*xy, z], atol=1e-6)
    pos = ANYSKIN_5.positions_mm()
    assert pos[1, 0, 0] < 0 and pos[0, 1, 1] > 0 and np.isnan(pos[0, 0]).all()


def test_chips_from_reading_inverts_reading_from_chips():
    rng = np.random.default_rng(0)
    for layout in (SUPERMAG_4X4, ANYSKIN_5):
        chips = rng.normal(0, 300, (layout.n_chips, 3)).astype(np.float32)
        np.testing.assert_allclose(layout.chips_from_reading(layout.reading_from_chips(chips)), chips, atol=1e-3)


def test_saturation_and_temperatures_follow_the_chips():
    sat = np.zeros((5, 3), bool)
    sat[0, 0] = True  # centre chip x, turned 90 degrees: lands on pad y
    out = ANYSKIN_5.saturation_from_chips(sat)
    assert out.sum() == 1 and out[1, 1, 1]
    temps = ANYSKIN_5.cells_from_chips(np.arange(5, dtype=np.float32))
    assert temps[0, 1] == 3 and temps[2, 1] == 4 and np.isnan(temps[0, 0])


def test_a_board_whose_firmware_order_is_not_grid_order():
    # a 2x2 board wired column-major, one chip mounted upside down in the plane
    layout = Board(name="test-2x2", grid=(2, 2), pitch_mm=5.0, chips=(
        ChipSpec((0, 0), (-2.5, 2.5)), ChipSpec((1, 0), (-2.5, -2.5)),
        ChipSpec((0, 1), (2.5, 2.5), rotation_deg=180.0), ChipSpec((1, 1), (2.5, -2.5))))
    chips = np.array([[1, 2, 3], [4, 5, 6], [7, 8, 9], [10, 11, 12]], np.float32)
    reading = layout.reading_from_chips(chips)
    np.testing.assert_allclose(reading[1, 0], [4, 5, 6])
    np.testing.assert_allclose(reading[0, 1], [-7, -8, 9], atol=1e-6)


def test_bad_layouts_and_names_are_refused():
    with pytest.raises(ValueError, match="outside the 2x2 grid"):
        Board(name="x", grid=(2, 2), pitch_mm=5.0, chips=(ChipSpec((2, 0), (0, 0)),))
    with pytest.raises(ValueError, match="same cell"):
        Board(name="x", grid=(2, 2), pitch_mm=5.0,
                    chips=(ChipSpec((0, 0), (0, 0)), ChipSpec((0, 0), (1, 0))))
    with pytest.raises(ValueError, match="known boards: anyskin-5, .*supermag-4x4"):
        load_board("hexagon")
    grid = Board(name="g", grid=(2, 3), pitch_mm=4.0, chips=ChipGridSpec(rows=2, cols=3, pitch_mm=4.0).chips())
    assert grid.positions_mm()[1, 2].tolist() == [4.0, -2.0]
