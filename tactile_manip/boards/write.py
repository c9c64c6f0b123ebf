"""A board as the text of a board file: what ``fit-board`` writes, and :func:`~tactile_manip.boards.load.load_board`
reads back to the same board.

The tables are those of :mod:`tactile_manip.boards.spec`; ``[fit]`` is free-form and written with nested tables
(``[fit.rows]``) and arrays. numpy only.
"""

from __future__ import annotations

import json
import math
import textwrap
from typing import Any

from tactile_manip.boards.board import Board

_WRAP = 110  # longer strings are written over several lines


def board_toml(board: Board, *, header: str = "") -> str:
    """The board file text of ``board`` (chips listed one by one); ``header`` becomes leading ``#`` comments."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    lines += ["", "[board]", f"name = {_value(board.name)}", f"grid = {_value(list(board.grid))}",
              f"pitch_mm = {_value(board.pitch_mm)}", f"description = {_value(board.description)}",
              f"source = {_value(board.source)}"]
    for chip in board.chips:
        lines += ["", "[[chips]]", f"cell = {_value(list(chip.cell))}", f"position_mm = {_value(list(chip.position_mm))}"]
        lines.append(f"axes = {_value(list(chip.axes))}" if chip.axes is not None
                     else f"rotation_deg = {_value(chip.rotation_deg)}")
    lines += _table("chip", _fields(board.chip))
    lines += _table("wire", _fields(board.wire))
    if board.body is not None:
        body = _fields(board.body)
        magnets = body.pop("magnets")
        if board.body.kind == "magnets":
            body.pop("remanence_t")
        lines += _table("body", body)
        for magnet in magnets:
            lines += ["", "[[body.magnets]]", *(f"{k} = {_value(v)}" for k, v in magnet.items())]
    if board.layer is not None:
        lines += _table("layer", _fields(board.layer))
    if board.twin is not None:
        twin = _fields(board.twin)
        readout = twin.pop("readout")
        lines += _table("twin", twin)
        for r in readout:
            lines += ["", "[[twin.readout]]", *(f"{k} = {_value(v)}" for k, v in r.items())]
    if board.fit is not None:
        lines += _nested("fit", board.fit)
    return "\n".join(lines).lstrip("\n") + "\n"


def _fields(obj: Any) -> dict[str, Any]:
    from tactile_manip.config import to_dict

    return to_dict(obj)


def _table(name: str, values: dict[str, Any]) -> list[str]:
    return ["", f"[{name}]", *(f"{_key(k)} = {_value(v)}" for k, v in values.items() if v is not None)]


def _nested(name: str, values: dict[str, Any]) -> list[str]:
    plain = {k: v for k, v in values.items() if not isinstance(v, dict)}
    out = _table(name, plain)
    for key, value in values.items():
        if isinstance(value, dict):
            out += _nested(f"{name}.{_key(key)}", value)
    return out


def _key(key: str) -> str:
    return key if key.replace("_", "").replace("-", "").isalnum() else json.dumps(key)


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
        return repr(float(f"{v:.6g}")) if abs(v) >= 1e-4 or v == 0.0 else f"{v:.6g}"
    if isinstance(v, str):
        if len(v) > _WRAP and "\n" not in v:  # a multi-line basic string whose lines end in "\" reads as one line
            lines = textwrap.wrap(v, _WRAP, break_long_words=False, break_on_hyphens=False)
            body = " \\\n".join(json.dumps(line, ensure_ascii=False)[1:-1] for line in lines)
            return f'"""{body}"""'
        return json.dumps(v, ensure_ascii=False)  # a TOML basic string is JSON's escaping
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    if v is None:
        return '""'
    if hasattr(v, "item"):  # a numpy scalar
        return _value(v.item())
    raise TypeError(f"cannot write {type(v).__name__} to TOML")
