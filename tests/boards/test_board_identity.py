"""A board's identity is what its readings depend on, not its name: datasets and models carry it, and a model of
one board refuses data or a sensor of another, with one line naming both boards and what differs."""

from __future__ import annotations

from pathlib import Path

import pytest
from checks import assert_one_line_error

from tactile_manip.boards import load_board
from tactile_manip.boards.identity import (BoardMismatchError, check_same_board, record_of_metadata,
                                           record_of_provenance)
from tactile_manip.cli import main
from tactile_manip.data import load_dataset
from tactile_manip.errors import ConfigError

BOARDS = Path(__file__).resolve().parents[2] / "tactile_manip" / "boards"


def _board_file(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_the_fingerprint_follows_the_readings_not_the_name(tmp_path):
    text = (BOARDS / "eflesh.toml").read_text()
    renamed = load_board(_board_file(tmp_path, "a.toml", text.replace('name = "eflesh"', 'name = "my-cube"')))
    turned = load_board(_board_file(tmp_path, "b.toml", text.replace('name = "eflesh"', 'name = "my-cube"')
                                    .replace("rotation_deg = 90.0", "rotation_deg = 127.0", 1)))
    eflesh, anyskin = load_board("eflesh"), load_board("anyskin-5")
    assert renamed.fingerprint == eflesh.fingerprint  # a name is no part of it
    assert turned.fingerprint != eflesh.fingerprint
    assert anyskin.fingerprint != eflesh.fingerprint  # the same chips, read at other LSB sizes
    with pytest.raises(BoardMismatchError, match=r"chip 0's axis turn differ"):
        check_same_board("the model", eflesh.record, "the dataset", turned.record)
    with pytest.raises(BoardMismatchError, match=r"the model is of board 'eflesh' .* and the dataset of board "
                                                 r"'anyskin-5' .*: the LSB sizes \[2.4, 3.872\] against"):
        check_same_board("the model", eflesh.record, "the dataset", anyskin.record)
    check_same_board("the model", eflesh.record, "the dataset", renamed.record)
    check_same_board("the model", None, "the dataset", anyskin.record)  # unknown: nothing to compare


def test_a_file_may_not_take_a_shipped_boards_name_with_other_contents(tmp_path):
    text = (BOARDS / "supermag-4x4.toml").read_text()
    assert load_board(_board_file(tmp_path, "copy.toml", text)).fingerprint == load_board("supermag-4x4").fingerprint
    other = _board_file(tmp_path, "other.toml", text.replace("pitch_mm = 5.0", "pitch_mm = 5.5", 1))
    with pytest.raises(ConfigError, match="board.name 'supermag-4x4' is a shipped board's, but this file's"):
        load_board(other)


@pytest.mark.parametrize("name", ["my\u202ecube", "tab\there", "bell\x07", "zero\u200bwidth"])
def test_a_board_name_is_printable_without_control_characters(name, tmp_path):
    text = (BOARDS / "eflesh.toml").read_text().replace('name = "eflesh"', f'name = "{name}"'.encode(
        "unicode_escape").decode().replace("\\\\", "\\"), 1)
    with pytest.raises(ConfigError, match="printable"):
        load_board(_board_file(tmp_path, "n.toml", text))


def test_datasets_carry_their_boards_record(tmp_path):
    out = tmp_path / "e.npz"
    assert main(["simulate", "--board", "eflesh", "--presses", "4", "--out", str(out)]) == 0
    record = record_of_provenance(load_dataset(out).provenance)
    assert record is not None and record["fingerprint"] == load_board("eflesh").fingerprint
    assert record_of_provenance({"layout": "anyskin-5"})["name"] == "anyskin-5"  # a file from before records


def test_evaluate_refuses_a_model_of_another_board_in_one_line(tmp_path, capsys):
    pytest.importorskip("onnxruntime")
    data = tmp_path / "anyskin.npz"
    assert main(["simulate", "--board", "anyskin-5", "--presses", "6", "--out", str(data)]) == 0
    capsys.readouterr()
    model = BOARDS.parents[1] / "models" / "contact_eflesh.onnx"
    assert main(["evaluate", "--data", str(data), "--model", f"e={model}", "--out", str(tmp_path / "ev")]) == 2
    assert_one_line_error(capsys.readouterr().err, "evaluate", "is of board 'eflesh'", "of board 'anyskin-5'",
                          "LSB sizes")
    assert not (tmp_path / "ev").exists()


def test_datasets_of_two_boards_are_not_joined(tmp_path, capsys):
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    assert main(["simulate", "--board", "anyskin-5", "--presses", "4", "--out", str(a)]) == 0
    assert main(["simulate", "--board", "eflesh", "--presses", "4", "--out", str(b)]) == 0
    from tactile_manip.data import load_datasets

    with pytest.raises(BoardMismatchError, match="dataset 1 is of board 'eflesh'"):
        load_datasets([a, b])


def test_a_sensor_of_another_board_is_refused_by_the_models(tmp_path):
    pytest.importorskip("onnxruntime")
    from tactile_manip.perception.contact import ContactEstimator

    contact = ContactEstimator(BOARDS.parents[1] / "models" / "contact_eflesh.onnx")
    contact.check_layout(load_board("eflesh"))
    with pytest.raises(BoardMismatchError, match="the sensor of board 'anyskin-5'"):
        contact.check_layout(load_board("anyskin-5"))
    assert record_of_metadata(contact.metadata)["name"] == "eflesh"
