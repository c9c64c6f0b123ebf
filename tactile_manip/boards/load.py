"""Boards by name or file: the shipped board files, ``generic:N``, and a user's own TOML file.

:func:`load_board` takes what ``--board`` takes:

- a shipped board's name (:func:`board_names`: ``supermag-4x4``, ``anyskin-5``, ``eflesh``), read from the
  ``.toml`` file of that name beside this module;
- ``generic:N``: N 3-axis chips in firmware order, in a (1, N) reading, without geometry: enough to import,
  train and evaluate a board nobody has described; simulation refuses it;
- a path to a board file (any name ending in ``.toml``, or an existing file).

Every problem with a file (missing, unknown or mistyped field, overlapping chips, a cell outside the grid, a
magnet below the chips) raises :class:`~tactile_manip.errors.ConfigError` naming the file and the field.
"""

from __future__ import annotations

import functools
import math
import re
from pathlib import Path

import numpy as np

from tactile_manip.boards.board import GENERIC_PREFIX, Board
from tactile_manip.boards.spec import BodySpec, BoardFile, BoardHeader, ChipModelSpec, ChipSpec, LayerSpec, WireSpec
from tactile_manip.config import load_config
from tactile_manip.errors import ConfigError

BOARD_DIR = Path(__file__).resolve().parent
DEFAULT_BOARD = "supermag-4x4"  # the board firmware/ speaks and every shipped model reads
MAX_GENERIC_CHIPS = 64
# Chip centres closer than this overlap: the MLX90393's package is 3 x 3 mm.
MIN_CHIP_SPACING_MM = 3.0


def board_names() -> list[str]:
    """The shipped boards' names (their files beside this module), sorted."""
    return sorted(p.stem for p in BOARD_DIR.glob("*.toml"))


def load_board(name_or_path: str | Path) -> Board:
    """The board a ``--board`` value names: a shipped name, ``generic:N`` or a board file's path.

    Raises:
        ConfigError: an unknown name, a bad ``generic:N``, or a file that is missing or does not describe a
            valid board (the message names the file and the field).
    """
    text = str(name_or_path)
    if text.startswith(GENERIC_PREFIX):
        return generic_board(text)
    if text in board_names():
        return _shipped(text)
    path = Path(text)
    if path.suffix == ".toml" or path.is_file():
        return board_from_file(path)
    raise ConfigError(f"unknown board {text!r}; known boards: {', '.join(board_names())}, or generic:N (N chips "
                      "without geometry), or a board file's path (.toml, docs/your_board.md)")


@functools.lru_cache(maxsize=None)
def _shipped(name: str) -> Board:
    return board_from_file(BOARD_DIR / f"{name}.toml")


def generic_board(text: str) -> Board:
    """``generic:N``: N chips in firmware order feeding a (1, N) reading, axes as sent, positions unknown."""
    count = text[len(GENERIC_PREFIX):]
    if not re.fullmatch(r"[0-9]+", count) or not 1 <= int(count) <= MAX_GENERIC_CHIPS:
        raise ConfigError(f"board {text!r}: generic:N takes a chip count N from 1 to {MAX_GENERIC_CHIPS}, "
                          "e.g. generic:10 for a 30-channel board")
    n = int(count)
    chips = tuple(ChipSpec(cell=(0, i), position_mm=(math.nan, math.nan)) for i in range(n))
    return Board(name=f"{GENERIC_PREFIX}{n}", grid=(1, n), pitch_mm=1.0, chips=chips, chip=ChipModelSpec(),
                 wire=WireSpec(format="anyskin", baudrate=115200),
                 description=f"{n} 3-axis chips without geometry")


def board_from_file(path: str | Path) -> Board:
    """Read and check the board file at ``path`` (see :mod:`tactile_manip.boards.spec` for its tables)."""
    path = Path(path)
    spec = load_config(path, BoardFile)
    where = str(path)
    if bool(spec.chips) == (spec.chip_grid is not None):
        raise ConfigError(f"{where}: give the chips either as [[chips]] entries or as one [chip_grid], "
                          f"{'not both' if spec.chips else 'got neither'}")
    chips = spec.chips or spec.chip_grid.chips()  # type: ignore[union-attr]
    _check_chips(where, spec.board, chips)
    if (spec.body is None) != (spec.layer is None):
        present, absent = ("[body]", "[layer]") if spec.body is not None else ("[layer]", "[body]")
        raise ConfigError(f"{where}: {present} without {absent}: simulation needs both (or leave both out)")
    if spec.body is not None and spec.layer is not None:
        _check_magnets(where, spec.body, spec.layer)
    if spec.twin is not None and spec.twin.readout and len(spec.twin.readout) != len(chips):
        raise ConfigError(f"{where}: [[twin.readout]] has {len(spec.twin.readout)} entries for {len(chips)} chips; "
                          "give one per chip, in firmware order")
    head = spec.board
    board = Board(name=head.name, grid=head.grid, pitch_mm=head.pitch_mm, chips=chips, chip=spec.chip,
                  wire=spec.wire, body=spec.body, layer=spec.layer, twin=spec.twin, fit=spec.fit,
                  description=head.description,
                  source=head.source, path=path)
    _check_name(where, board, path)
    return board


def _check_name(where: str, board: Board, path: Path) -> None:
    """A file may take a shipped board's name only with that board's contents (its own copy, say): a name is how
    people and files refer to a board, and a second board under it would pass for the first."""
    if board.name not in board_names() or path.resolve() == (BOARD_DIR / f"{board.name}.toml").resolve():
        return
    shipped = _shipped(board.name)
    fields = ("grid", "pitch_mm", "chips", "chip", "wire", "body", "layer")
    differ = [f for f in fields if getattr(board, f) != getattr(shipped, f)]
    if differ:
        raise ConfigError(f"{where}: board.name {board.name!r} is a shipped board's, but this file's "
                          f"{', '.join(differ)} differ from it; give your board a name of its own")


def _check_chips(where: str, head: BoardHeader, chips: tuple[ChipSpec, ...]) -> None:
    rows, cols = head.grid
    if len(chips) > rows * cols:
        raise ConfigError(f"{where}: {len(chips)} chips do not fit the {rows}x{cols} reading grid")
    seen: dict[tuple[int, int], int] = {}
    for i, chip in enumerate(chips):
        r, c = chip.cell
        if not (0 <= r < rows and 0 <= c < cols):
            raise ConfigError(f"{where}: chips[{i}].cell {list(chip.cell)} is outside the {rows}x{cols} grid")
        if chip.cell in seen:
            raise ConfigError(f"{where}: chips[{seen[chip.cell]}] and chips[{i}] feed the same cell {list(chip.cell)}")
        seen[chip.cell] = i
    xy = np.array([c.position_mm for c in chips], dtype=np.float64)
    if np.isnan(xy).any():
        raise ConfigError(f"{where}: every chip needs its position_mm (a board without geometry is generic:N)")
    gaps = np.linalg.norm(xy[:, None] - xy[None], axis=-1) + np.diag(np.full(len(chips), np.inf))
    i, j = np.unravel_index(np.argmin(gaps), gaps.shape)
    if gaps[i, j] < MIN_CHIP_SPACING_MM:
        i, j = sorted((int(i), int(j)))
        raise ConfigError(f"{where}: chips[{i}] and chips[{j}] overlap: their centres are {gaps[i, j]:.2f} mm apart, "
                          f"less than a chip's {MIN_CHIP_SPACING_MM:g} mm package")


def _check_magnets(where: str, body: BodySpec, layer: LayerSpec) -> None:
    """Each magnet's centre lies in the layer (the layer carries it), and no magnet reaches the chips."""
    chip_z_mm = -(layer.thickness_mm + layer.gap_mm)
    for i, magnet in enumerate(body.magnets):
        half_height = (magnet.size_mm[1] if magnet.shape == "cylinder" else magnet.size_mm[2]) / 2
        if magnet.position_mm[2] - half_height < chip_z_mm:
            raise ConfigError(f"{where}: body.magnets[{i}] reaches below the chips' plane (z = {chip_z_mm:g} mm); "
                              "magnets sit above the chips, in or on the layer")
        if not -layer.thickness_mm <= magnet.position_mm[2] <= 0.0:
            raise ConfigError(f"{where}: body.magnets[{i}]'s centre z = {magnet.position_mm[2]:g} mm is outside the "
                              f"layer (-{layer.thickness_mm:g} to 0 mm): the layer carries its magnets")
        if magnet.shape == "cylinder" and any(magnet.polarisation_t[:2]):
            raise ConfigError(f"{where}: body.magnets[{i}] is a cylinder polarised off its axis; give "
                              "polarisation_t = [0, 0, J] (along the pad normal), or describe it as a cuboid")
