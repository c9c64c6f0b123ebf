"""Board layouts: where each chip of a board sits in the pad frame and which cell of the reading it feeds.

Readings keep the ``(rows, cols, 3)`` layout of docs/design.md, Conventions (row 0 at +y, column 0 at -x, axes in
the pad frame). A board's firmware sends its chips in its own order, each chip in its own axes; a
:class:`BoardLayout` lists the chips in that order, each with its reading cell, its position (mm) and its
rotation about the pad normal, and turns a ``(n_chips, 3)`` frame into a reading. Cells no chip feeds stay 0
and are False in :attr:`BoardLayout.mask`.

Layouts come from board files (:mod:`tactile_manip.boards`): :func:`get_layout` takes a shipped board's name
(``supermag-4x4``, the default, whose conversion is a reshape, so the SuperMag pipeline does no extra work;
``anyskin-5``, the five-chip cross of the ReSkin/AnySkin boards in a (3, 3, 3) reading with its corners unused;
``eflesh``, that board under the eFlesh cube), ``generic:N`` (N chips in a (1, N) reading, no geometry) or the
path of a user's board file. :data:`LAYOUTS` holds the shipped ones by name.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tactile_manip.boards import Board, ChipSpec, board_names, load_board

ANYSKIN_PITCH_MM = 7.0  # centre-to-neighbour chip distance of the 5X board (an estimate: boards/anyskin-5.toml)

#: One chip of a board, in firmware order: its reading ``cell`` (row, col), ``position_mm`` (x, y) in the pad
#: frame, and its axes in the pad's (``axes``, or the counter-clockwise ``rotation_deg`` about the pad normal:
#: a field along the chip's +x reads along pad direction (cos, sin) of this angle).
ChipPlacement = ChipSpec


@dataclass(frozen=True, eq=False)
class BoardLayout:
    """A board's chips (firmware order) mapped onto a ``grid`` of reading cells.

    Attributes:
        name: the layout's name, stored in recordings and model metadata.
        grid: (rows, cols) of the reading.
        chips: one placement per chip, in the order the firmware sends them.
        pitch_mm: distance between neighbouring reading cells, mm (for plots).
    """

    name: str
    grid: tuple[int, int]
    chips: tuple[ChipPlacement, ...]
    pitch_mm: float
    _index: np.ndarray = field(init=False, repr=False)
    _rot: np.ndarray = field(init=False, repr=False)
    _identity: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        rows, cols = self.grid
        if not self.name or rows < 1 or cols < 1 or not self.chips:
            raise ValueError(f"BoardLayout needs a name, a grid >= (1, 1) and chips, got {self.name!r}, "
                             f"{self.grid}, {len(self.chips)} chips")
        cells = [c.cell for c in self.chips]
        for cell in cells:
            if not (0 <= cell[0] < rows and 0 <= cell[1] < cols):
                raise ValueError(f"BoardLayout {self.name!r}: cell {cell} is outside the {rows}x{cols} grid")
        if len(set(cells)) != len(cells):
            raise ValueError(f"BoardLayout {self.name!r}: two chips feed the same cell")
        index = np.array([r * cols + c for r, c in cells], dtype=np.intp)
        rot = np.stack([c.matrix() for c in self.chips])  # exact zeros at right angles (saturation maps cleanly)
        object.__setattr__(self, "_index", index)
        object.__setattr__(self, "_rot", rot.astype(np.float32))
        identity = len(self.chips) == rows * cols and bool((index == np.arange(rows * cols)).all()) \
            and bool((rot == np.eye(3)).all())
        object.__setattr__(self, "_identity", identity)

    @property
    def n_chips(self) -> int:
        return len(self.chips)

    @property
    def shape(self) -> tuple[int, int, int]:
        """The reading's shape, (rows, cols, 3)."""
        return (*self.grid, 3)

    @property
    def mask(self) -> np.ndarray:
        """(rows, cols) bool, True at the cells a chip feeds."""
        m = np.zeros(self.grid[0] * self.grid[1], bool)
        m[self._index] = True
        return m.reshape(self.grid)

    def positions_mm(self) -> np.ndarray:
        """(rows, cols, 2) chip centres (x, y) in the pad frame, mm; NaN at unused cells."""
        out = np.full((self.grid[0] * self.grid[1], 2), np.nan)
        out[self._index] = [c.position_mm for c in self.chips]
        return out.reshape(*self.grid, 2)

    def reading_from_chips(self, chips_ut: np.ndarray) -> np.ndarray:
        """(n_chips, 3) fields in chip axes, firmware order -> (rows, cols, 3) float32 in pad axes (unused cells 0).

        On an identity layout a float32 input comes back as a view (the default board's frames cost a reshape).
        """
        if self._identity:
            return np.asarray(chips_ut, dtype=np.float32).reshape(self.shape)
        chips = np.asarray(chips_ut, dtype=np.float32)
        out = np.zeros((self.grid[0] * self.grid[1], 3), np.float32)
        out[self._index] = np.einsum("nij,nj->ni", self._rot, chips)
        return out.reshape(self.shape)

    def readings_from_chips(self, chips_ut: np.ndarray) -> np.ndarray:
        """(M, n_chips, 3) frames in chip axes, firmware order -> (M, rows, cols, 3) float32 readings in pad axes
        (unused cells 0): :meth:`reading_from_chips` for a stack of frames (a probe log, a recording)."""
        chips = np.asarray(chips_ut, dtype=np.float32)
        if chips.ndim != 3 or chips.shape[1:] != (self.n_chips, 3):
            raise ValueError(f"layout {self.name}: expected frames of shape (M, {self.n_chips}, 3), got {chips.shape}")
        m = chips.shape[0]
        if self._identity:
            return chips.reshape(m, *self.shape)
        out = np.zeros((m, self.grid[0] * self.grid[1], 3), np.float32)
        out[:, self._index] = np.einsum("nij,mnj->mni", self._rot, chips)
        return out.reshape(m, *self.shape)

    def chips_from_reading(self, reading_ut: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`reading_from_chips`: (rows, cols, 3) pad-axes field -> (n_chips, 3) chip axes."""
        r = np.asarray(reading_ut, dtype=np.float32).reshape(-1, 3)
        if self._identity:
            return r.copy()
        return np.einsum("nji,nj->ni", self._rot, r[self._index])

    def saturation_from_chips(self, saturated: np.ndarray) -> np.ndarray:
        """(n_chips, 3) bool in chip axes -> (rows, cols, 3) bool: a pad channel is saturated if any chip channel
        it is made of is."""
        sat = np.asarray(saturated, dtype=bool)
        if self._identity:
            return sat.reshape(self.shape)
        if not sat.any():  # the usual case, without the channel mixing below
            return np.zeros(self.shape, bool)
        out = np.zeros((self.grid[0] * self.grid[1], 3), bool)
        out[self._index] = np.einsum("nij,nj->ni", np.abs(self._rot) > 0, sat.astype(np.float32)) > 0
        return out.reshape(self.shape)

    def cells_from_chips(self, values: np.ndarray, fill: float = np.nan) -> np.ndarray:
        """(n_chips,) per-chip scalars (e.g. temperatures) -> (rows, cols) float32, ``fill`` at unused cells."""
        v = np.asarray(values, dtype=np.float32)
        if self._identity:
            return v.reshape(self.grid)
        out = np.full(self.grid[0] * self.grid[1], fill, np.float32)
        out[self._index] = v
        return out.reshape(self.grid)


def layout_from_board(board: Board) -> BoardLayout:
    """The layout of a board (its chips onto its reading grid)."""
    return BoardLayout(name=board.name, grid=board.grid, chips=board.chips, pitch_mm=board.pitch_mm)


def grid_layout(name: str, *, rows: int, cols: int, pitch_mm: float) -> BoardLayout:
    """Chips row-major over a rows x cols grid centred on the pad, axes along the pad's (the SuperMag board)."""
    chips = tuple(ChipPlacement(cell=(r, c),
                                position_mm=((c - (cols - 1) / 2) * pitch_mm, ((rows - 1) / 2 - r) * pitch_mm))
                  for r in range(rows) for c in range(cols))
    return BoardLayout(name=name, grid=(rows, cols), chips=chips, pitch_mm=pitch_mm)


def cross_layout(name: str, *, pitch_mm: float,
                 rotations_deg: tuple[float, ...] = (90.0, 90.0, 180.0, -90.0, 0.0)) -> BoardLayout:
    """The five-chip cross (centre, left, right, up, down) in a 3x3 reading (the ReSkin/AnySkin boards)."""
    cells = ((1, 1), (1, 0), (1, 2), (0, 1), (2, 1))
    chips = tuple(ChipPlacement(cell=cell, position_mm=((cell[1] - 1) * pitch_mm, (1 - cell[0]) * pitch_mm),
                                rotation_deg=rot) for cell, rot in zip(cells, rotations_deg, strict=True))
    return BoardLayout(name=name, grid=(3, 3), chips=chips, pitch_mm=pitch_mm)


LAYOUTS: dict[str, BoardLayout] = {name: layout_from_board(load_board(name)) for name in board_names()}
SUPERMAG_4X4 = LAYOUTS["supermag-4x4"]
ANYSKIN_5 = LAYOUTS["anyskin-5"]
DEFAULT_LAYOUT = SUPERMAG_4X4.name


def get_layout(name: str) -> BoardLayout:
    """The layout of the board ``name`` names: a shipped board, ``generic:N`` or a board file's path.

    Raises:
        ValueError (a :class:`~tactile_manip.errors.ConfigError`): an unknown board or a bad board file, named.
    """
    if name in LAYOUTS:
        return LAYOUTS[name]
    return layout_from_board(load_board(name))
