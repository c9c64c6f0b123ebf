"""Boards: any magnetic skin's board, described as data (docs/your_board.md).

``load_board("eflesh")``, ``load_board("generic:10")`` or ``load_board("my_board.toml")`` gives a
:class:`Board`: its chips in firmware order (reading cell, position in mm, axis map into the pad frame) and the
map of its frames onto readings, its chip model and wire format, and, for simulation, its magnetic body and
compliant layer. The one board type of the package: the drivers, the simulator, the estimators and the scenes
all take it. numpy only.
"""

from tactile_manip.boards.board import GENERIC_PREFIX, Board
from tactile_manip.boards.load import DEFAULT_BOARD, board_from_file, board_names, generic_board, load_board
from tactile_manip.boards.spec import BodySpec, ChipModelSpec, ChipSpec, LayerSpec, MagnetSpec, WireSpec

__all__ = [
    "DEFAULT_BOARD",
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
