"""The board: a magnetic skin's chips, reading grid, chip model and wire format, and, where its file describes
them, the magnetic body and compliant layer that simulation needs.

Readings keep the ``(rows, cols, 3)`` layout of docs/design.md, Conventions (row 0 at +y, column 0 at -x, axes in
the pad frame). A board's firmware sends its chips in its own order, each chip in its own axes; a :class:`Board`
lists the chips in that order, each with its reading cell, its position (mm) and its axes in the pad's, and
turns a ``(n_chips, 3)`` frame into a reading. Cells no chip feeds stay 0 and are False in :attr:`Board.mask`.
On the SuperMag board (chips row-major, axes along the pad's) that conversion is a reshape, so its pipeline does
no extra work.

Boards come from board files (:func:`~tactile_manip.boards.load.load_board`); numpy only.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.boards.spec import BodySpec, ChipSpec, LayerSpec, TwinSpec, WireSpec
from tactile_manip.chips import ChipModelSpec
from tactile_manip.errors import ConfigError

GENERIC_PREFIX = "generic:"


@dataclass(frozen=True, eq=False)
class Board:
    """A checked board: its chips (firmware order) mapped onto a ``grid`` of reading cells, its chip model and
    wire format, and, where the file describes them, the magnetic body and compliant layer that simulation needs.

    Attributes:
        name: the board's name, stored in recordings, datasets and model metadata.
        grid: (rows, cols) of the reading.
        pitch_mm: distance between neighbouring reading cells, mm (plots).
        chips: one per chip, in the order the firmware sends them.
        chip: the magnetometer's LSB sizes, rail, rate and noise.
        wire: the serial backend's wire format and baud rate.
        body: the magnetic body (None: not simulatable).
        layer: the compliant layer (None: not simulatable).
        twin: a fitted board's rig frame, press kernel and chip readouts (``[twin]``; None: not fitted).
        fit: what a fitted board was fitted on, and its residuals (``[fit]``, free-form; None: not fitted).
        path: the file it came from (None for ``generic:N`` and boards built in code).

    Raises:
        ValueError: no name, an empty grid or no chips, a cell outside the grid, or two chips on one cell.
    """

    name: str
    grid: tuple[int, int]
    pitch_mm: float
    chips: tuple[ChipSpec, ...]
    chip: ChipModelSpec = field(default_factory=ChipModelSpec)
    wire: WireSpec = field(default_factory=WireSpec)
    body: BodySpec | None = None
    layer: LayerSpec | None = None
    twin: TwinSpec | None = None
    fit: dict[str, Any] | None = None
    description: str = ""
    source: str = ""
    path: Path | None = None
    _index: np.ndarray = field(init=False, repr=False)
    _rot: np.ndarray = field(init=False, repr=False)
    _identity: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        rows, cols = self.grid
        if not self.name or rows < 1 or cols < 1 or not self.chips:
            raise ValueError(f"a board needs a name, a grid >= (1, 1) and chips, got {self.name!r}, "
                             f"{self.grid}, {len(self.chips)} chips")
        cells = [c.cell for c in self.chips]
        for cell in cells:
            if not (0 <= cell[0] < rows and 0 <= cell[1] < cols):
                raise ValueError(f"board {self.name!r}: cell {cell} is outside the {rows}x{cols} grid")
        if len(set(cells)) != len(cells):
            raise ValueError(f"board {self.name!r}: two chips feed the same cell")
        index = np.array([r * cols + c for r, c in cells], dtype=np.intp)
        rot = np.stack([c.matrix() for c in self.chips])  # exact zeros at right angles (saturation maps cleanly)
        object.__setattr__(self, "_index", index)
        object.__setattr__(self, "_rot", rot.astype(np.float32))
        identity = len(self.chips) == rows * cols and bool((index == np.arange(rows * cols)).all()) \
            and bool((rot == np.eye(3)).all())
        object.__setattr__(self, "_identity", identity)

    # -- what the board is ------------------------------------------------------------------------------------

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

    @property
    def generic(self) -> bool:
        return self.name.startswith(GENERIC_PREFIX)

    @functools.cached_property
    def record(self) -> dict:
        """Name, fingerprint and identity (:mod:`tactile_manip.boards.identity`): what datasets and models of this
        board carry, and what a reading of another board is told apart by."""
        from tactile_manip.boards.identity import board_record

        return board_record(self)

    @property
    def fingerprint(self) -> str:
        """16 hex of what this board's readings depend on (grid, chips' cells, places and turns, LSB sizes, wire
        format and unit); not its name."""
        return self.record["fingerprint"]

    @property
    def simulatable(self) -> bool:
        """Whether the file describes a magnetic body, a compliant layer and every chip's position."""
        return self.body is not None and self.layer is not None and not self.generic

    def require_simulation(self) -> None:
        """Raise ConfigError (one line) unless the board can be simulated."""
        if self.generic:
            raise ConfigError(f"board {self.name} has no geometry and cannot be simulated: describe the board in a "
                              "board file (docs/your_board.md) with its chips' positions, [body] and [layer]")
        if not self.simulatable:
            missing = " and ".join(t for t, v in (("[body]", self.body), ("[layer]", self.layer)) if v is None)
            raise ConfigError(f"board {self.name} ({self.path}) has no {missing}: simulation needs the magnetic "
                              "body and the compliant layer (docs/your_board.md)")

    def chip_positions_mm(self) -> np.ndarray:
        """(n_chips, 3) chip sensing points (x, y, z) in the pad frame, mm, firmware order; z below the layer
        (NaN without a layer or for a board without geometry)."""
        xy = np.array([c.position_mm for c in self.chips], dtype=np.float64)
        z = -(self.layer.thickness_mm + self.layer.gap_mm) if self.layer is not None else math.nan
        return np.column_stack([xy, np.full(len(self.chips), z)])

    def positions_mm(self) -> np.ndarray:
        """(rows, cols, 2) chip centres (x, y) in the pad frame, mm; NaN at unused cells."""
        out = np.full((self.grid[0] * self.grid[1], 2), np.nan)
        out[self._index] = [c.position_mm for c in self.chips]
        return out.reshape(*self.grid, 2)

    def chip_matrices(self) -> np.ndarray:
        """(n_chips, 3, 3) float64, each chip's axes -> pad axes, firmware order."""
        return np.stack([c.matrix() for c in self.chips])

    # -- frames (firmware order, chip axes) to readings (grid, pad axes) -------------------------------------

    def reading_from_chips(self, chips_ut: np.ndarray) -> np.ndarray:
        """(n_chips, 3) fields in chip axes, firmware order -> (rows, cols, 3) float32 in pad axes (unused cells 0).

        On an identity board a float32 input comes back as a view (the default board's frames cost a reshape).
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
            raise ValueError(f"board {self.name}: expected frames of shape (M, {self.n_chips}, 3), got {chips.shape}")
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

    def cells_from_pad(self, pad_ut: np.ndarray) -> np.ndarray:
        """(n_chips, ...) per-chip values, firmware order -> (rows, cols, ...) on the grid, 0 at unused cells, the
        input's dtype: no change of axes (the simulator's pad-axes fields)."""
        values = np.asarray(pad_ut)
        if self._identity:
            return values.reshape(*self.grid, *values.shape[1:])
        out = np.zeros((self.grid[0] * self.grid[1], *values.shape[1:]), values.dtype)
        out[self._index] = values
        return out.reshape(*self.grid, *values.shape[1:])

    def chips_from_cells(self, cells: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`cells_from_pad`: (rows, cols, ...) -> (n_chips, ...), firmware order."""
        values = np.asarray(cells)
        return values.reshape(self.grid[0] * self.grid[1], *values.shape[2:])[self._index]

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
