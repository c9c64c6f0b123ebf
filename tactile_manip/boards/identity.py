"""A board's identity: what its readings depend on, as a record that datasets and models carry.

Two boards read the same where their reading grid, their chips (cell, place on the pad, axis turn), their chip
model's LSB sizes (the readings' unit and step) and their wire format are the same; the name, the description
and the magnets (which simulation needs, but a reading does not depend on) are not part of it. The
:func:`fingerprint` of that identity is what a dataset or a model is checked against, never the name: a model of
one board refuses another board's readings (:func:`check_same_board`), with one line that names both boards and
what differs.

A record is ``{"name": ..., "fingerprint": ..., "identity": {...}}`` (:func:`board_record`), JSON-ready; a dataset
keeps it in its provenance (``"board"``) and a model in its metadata (``"board"``). Files made before records
existed name only their board (``layout`` / ``board_layout``): :func:`record_of_name` rebuilds the record of a
shipped board from that name, as that board's file read then (:data:`TURNS_BEFORE_RECORDS_DEG`).

A shipped board's file can change (its chips' turns corrected, say); a model trained on it before then reads the
chips as they were, so :func:`check_model_of_current_board` refuses to load it against the file as it is now.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from typing import TYPE_CHECKING, Any

from tactile_manip.errors import ConfigError

if TYPE_CHECKING:
    from tactile_manip.boards.board import Board

UNIT = "uT"  # readings are microtesla
# Each chip's turn (deg, firmware order) in a shipped board's file while datasets and models named their board only,
# for the boards whose chips have changed since: a file of that time that names the board was made on these.
# eflesh: the AnySkin visualiser's turns, until the chips' axes were fitted to the eFlesh runs (eflesh.toml).
TURNS_BEFORE_RECORDS_DEG: dict[str, tuple[float, ...]] = {"eflesh": (90.0, 90.0, 180.0, -90.0, 0.0)}


class BoardMismatchError(ConfigError):
    """Data of one board met a model (or other data, or a sensor) of another."""


def identity(board: Board) -> dict[str, Any]:
    """What ``board``'s readings depend on (positions and turns rounded to a micrometre and a millidegree)."""
    chips = []
    for chip in board.chips:
        position = [None if not math.isfinite(v) else round(float(v), 3) for v in chip.position_mm]
        axes = [[round(float(v), 6) for v in row] for row in chip.matrix().tolist()]
        chips.append({"cell": [int(c) for c in chip.cell], "position_mm": position, "axes": axes})
    return {"grid": [int(v) for v in board.grid], "chips": chips, "wire_format": board.wire.format,
            "lsb_ut": [round(float(board.chip.lsb_xy_ut), 6), round(float(board.chip.lsb_z_ut), 6)], "unit": UNIT}


def fingerprint(ident: dict[str, Any]) -> str:
    """SHA-256 (first 16 hex) of an identity's canonical JSON."""
    return hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()[:16]


def board_record(board: Board) -> dict[str, Any]:
    """The record datasets and models carry: name, fingerprint and identity."""
    ident = identity(board)
    return {"name": board.name, "fingerprint": fingerprint(ident), "identity": ident}


def record_of_name(name: Any) -> dict[str, Any] | None:
    """The record of the board a file made before records existed names (a shipped board or ``generic:N``), or
    None when the name is no such board."""
    from tactile_manip.boards.load import load_board

    if not isinstance(name, str) or not name:
        return None
    try:
        if not _known(name):
            return None
        board = load_board(name)
    except ConfigError:
        return None
    if name in TURNS_BEFORE_RECORDS_DEG:
        chips = tuple(dataclasses.replace(chip, axes=None, rotation_deg=turn)
                      for chip, turn in zip(board.chips, TURNS_BEFORE_RECORDS_DEG[name], strict=True))
        board = dataclasses.replace(board, chips=chips)
    return board_record(board)


def record_of_provenance(provenance: dict[str, Any]) -> dict[str, Any] | None:
    """The board record a dataset's provenance holds (``board``), or the one its board's name gives (``layout``,
    datasets made before records existed); None where neither says."""
    record = provenance.get("board")
    if isinstance(record, dict) and isinstance(record.get("fingerprint"), str):
        return record
    return record_of_name(provenance.get("layout"))


def record_of_metadata(metadata: dict[str, Any]) -> dict[str, Any] | None:
    """The board record a model's metadata holds (``board``), or the one its ``board_layout`` name gives (models
    exported before records existed); None where neither says."""
    record = metadata.get("board")
    if isinstance(record, dict) and isinstance(record.get("fingerprint"), str):
        return record
    return record_of_name(metadata.get("board_layout"))


def _known(name: str) -> bool:
    from tactile_manip.boards.load import GENERIC_PREFIX, board_names

    return name in board_names() or name.startswith(GENERIC_PREFIX)


def difference(a: dict[str, Any], b: dict[str, Any]) -> str:
    """What differs between two identities, in a few words ("chip 0's axes", "the grid 3x3 against 4x4", ...)."""
    if a.get("grid") != b.get("grid"):
        return f"the reading grid {_grid(a)} against {_grid(b)}"
    chips_a, chips_b = a.get("chips", []), b.get("chips", [])
    if len(chips_a) != len(chips_b):
        return f"{len(chips_a)} chips against {len(chips_b)}"
    for i, (ca, cb) in enumerate(zip(chips_a, chips_b)):
        for key, what in (("cell", "cell"), ("position_mm", "place"), ("axes", "axis turn")):
            if ca.get(key) != cb.get(key):
                return f"chip {i}'s {what}"
    for key, what in (("wire_format", "wire format"), ("lsb_ut", "LSB sizes"), ("unit", "unit")):
        if a.get(key) != b.get(key):
            return f"the {what} {a.get(key)} against {b.get(key)}"
    return "their identities"


def _grid(ident: dict[str, Any]) -> str:
    grid = ident.get("grid") or ["?", "?"]
    return f"{grid[0]}x{grid[1]}"


def check_same_board(what_a: str, a: dict[str, Any] | None, what_b: str, b: dict[str, Any] | None) -> None:
    """Refuse ``a`` and ``b`` (records, or None where unknown: nothing is checked then) of different boards.

    Raises:
        BoardMismatchError: one line: ``what_a`` is of board X, ``what_b`` of board Y, and what differs.
    """
    if a is None or b is None or a.get("fingerprint") == b.get("fingerprint"):
        return
    raise BoardMismatchError(f"{what_a} is of board {a.get('name')!r} ({a.get('fingerprint')}) and {what_b} of board "
                             f"{b.get('name')!r} ({b.get('fingerprint')}): "
                             f"{difference(a.get('identity', {}), b.get('identity', {}))} differ; a model reads only "
                             "the readings of the board it was trained on")


def check_model_of_current_board(what: str, metadata: dict[str, Any], recipe: str) -> None:
    """Refuse a model (``metadata``) of a shipped board whose file no longer reads as it did when the model was
    trained: the fingerprint its metadata stores (or, for a model that names its board only, the one that board's
    file had then) against that board's file now. A model of a user's own board file is checked against a
    sensor's board instead (:func:`check_board_of`).

    Raises:
        BoardMismatchError: one line naming both fingerprints, what differs and ``recipe``, how to retrain it.
    """
    from tactile_manip.boards.load import board_names, load_board

    mine = record_of_metadata(metadata) if isinstance(metadata, dict) else None
    if mine is None or mine.get("name") not in board_names():
        return
    name, now = mine["name"], load_board(mine["name"]).record
    if mine["fingerprint"] == now["fingerprint"]:
        return
    raise BoardMismatchError(f"{what} was trained on board {name!r} as its file read then ({mine['fingerprint']}), "
                             f"but tactile_manip/boards/{name}.toml now reads as {now['fingerprint']} "
                             f"({difference(mine.get('identity', {}), now['identity'])} differ): it would misread "
                             f"the board's readings; retrain it by its recipe ({recipe}) on data made with the "
                             "current file")


def check_board_of(what: str, metadata: dict[str, Any], board: Any) -> bool:
    """For a model's ``check_layout``: where ``board`` is a Board and the model's ``metadata`` gives its board's
    record, refuse a board of another identity (:class:`BoardMismatchError`) and return True; else return False
    (the caller compares names)."""
    record = getattr(board, "record", None)
    mine = record_of_metadata(metadata) if isinstance(metadata, dict) else None
    if record is None or mine is None:
        return False
    check_same_board(what, mine, "the sensor", record)
    return True
