"""Board files: any magnetic skin's board, described as data (docs/your_board.md).

``load_board("eflesh")``, ``load_board("generic:10")`` or ``load_board("my_board.toml")`` gives a
:class:`Board`: its chips in firmware order (reading cell, position in mm, axis map into the pad frame), chip
model, wire format, and, for simulation, its magnetic body and compliant layer. The sensors layer turns a board
into the :class:`~tactile_manip.boards.layout.BoardLayout` that maps frames onto readings. numpy only.
"""

from tactile_manip.boards.load import (
    GENERIC_PREFIX,
    Board,
    board_from_file,
    board_names,
    generic_board,
    load_board,
)
from tactile_manip.boards.spec import BodySpec, ChipModelSpec, ChipSpec, LayerSpec, MagnetSpec, WireSpec

__all__ = [
    "GENERIC_PREFIX",
    "BodySpec",
    "Board",
    "ChipModelSpec",
    "ChipSpec",
    "LayerSpec",
    "MagnetSpec",
    "WireSpec",
    "board_from_file",
    "board_names",
    "generic_board",
    "load_board",
]
