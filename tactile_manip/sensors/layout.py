"""Board layouts, where the sensors layer has always found them: the layouts now live with the board files in
:mod:`tactile_manip.boards.layout` (the data layer reads them too), and this module names the same objects."""

from tactile_manip.boards.layout import (
    ANYSKIN_5,
    ANYSKIN_PITCH_MM,
    DEFAULT_LAYOUT,
    LAYOUTS,
    SUPERMAG_4X4,
    BoardLayout,
    ChipPlacement,
    cross_layout,
    get_layout,
    grid_layout,
    layout_from_board,
)

__all__ = ["ANYSKIN_5", "ANYSKIN_PITCH_MM", "DEFAULT_LAYOUT", "LAYOUTS", "SUPERMAG_4X4", "BoardLayout", "ChipPlacement",
           "cross_layout", "get_layout", "grid_layout", "layout_from_board"]
