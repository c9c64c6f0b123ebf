"""Property-based fuzzing of board files: a shipped board's file with one value, key or line damaged loads as a
board or is refused with a ConfigError naming the file; never another exception."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactile_manip.boards import load_board
from tactile_manip.errors import ConfigError

BOARDS = Path(__file__).resolve().parents[2] / "tactile_manip" / "boards"
TEXTS = {p.stem: p.read_text() for p in sorted(BOARDS.glob("*.toml"))}
FUZZ = settings(max_examples=int(os.environ.get("TACTILE_MANIP_FUZZ_EXAMPLES", "80")), derandomize=True,
                deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
_VALUE = re.compile(r"(?m)^(\s*[A-Za-z_]+\s*=\s*)(.+)$")
_REPLACEMENTS = st.sampled_from(["nan", "inf", "-inf", "1e300", "-1", "0", "\"\"", "\"\\u202e\"", "[]", "[nan, 0]",
                                 "[1, 2, 3, 4]", "true", "\"x\"", "{}", "[[1]]", "1e-300", "-0.0", "99999999999"])


@st.composite
def _damaged(draw):
    name = draw(st.sampled_from(sorted(TEXTS)))
    lines = TEXTS[name].splitlines()
    values = [i for i, line in enumerate(lines) if _VALUE.match(line) and not line.lstrip().startswith("#")]
    how = draw(st.sampled_from(["value", "value", "value", "drop", "duplicate", "bom", "truncate"]))
    i = draw(st.sampled_from(values))
    if how == "value":
        lines[i] = _VALUE.sub(lambda m: m.group(1) + draw(_REPLACEMENTS), lines[i])
    elif how == "drop":
        del lines[i]
    elif how == "duplicate":
        lines.insert(i, lines[i])
    elif how == "truncate":
        lines = lines[:i]
    text = "\n".join(lines) + "\n"
    return ("\ufeff" + text) if how == "bom" else text


@FUZZ
@given(text=_damaged())
def test_a_damaged_board_file_loads_or_is_refused_naming_the_file(text, tmp_path_factory):
    path = tmp_path_factory.mktemp("board") / "mine.toml"
    path.write_text(text, encoding="utf-8")
    try:
        board = load_board(path)
    except ConfigError as e:
        assert str(path) in str(e) or path.name in str(e), e
        assert "\n" not in str(e).strip(), e  # one line
        return
    assert board.n_chips >= 1


@pytest.mark.parametrize("name", sorted(TEXTS))
def test_every_shipped_board_file_loads(name, tmp_path):
    path = tmp_path / f"{name}.toml"
    path.write_text(TEXTS[name])
    assert load_board(path).n_chips >= 1
