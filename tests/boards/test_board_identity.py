"""A board's identity is what its readings depend on, not its name: datasets and models carry it, and a model of
one board refuses data or a sensor of another, with one line naming both boards and what differs."""

from __future__ import annotations

from pathlib import Path

import pytest
from checks import assert_one_line_error

from tactile_manip.boards import load_board
from tactile_manip.boards.identity import (BoardMismatchError, check_same_board, record_of_metadata, record_of_name,
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
                                    .replace('axes = ["+y", "+x", "-z"]', 'rotation_deg = 127.0', 1)))
    eflesh, anyskin = load_board("eflesh"), load_board("anyskin-5")
    assert renamed.fingerprint == eflesh.fingerprint  # a name is no part of it
    assert turned.fingerprint != eflesh.fingerprint
    assert anyskin.fingerprint != eflesh.fingerprint  # the same places, other chip axes and LSB sizes
    with pytest.raises(BoardMismatchError, match=r"chip 0's axis turn differ"):
        check_same_board("the model", eflesh.record, "the dataset", turned.record)
    with pytest.raises(BoardMismatchError, match=r"the model is of board 'eflesh' .* and the dataset of board "
                                                 r"'anyskin-5' .*: chip 0's axis turn differ"):
        check_same_board("the model", eflesh.record, "the dataset", anyskin.record)
    before = record_of_name("eflesh")  # the file as a model naming its board only knew it: anyskin-5's chip turns
    assert before["fingerprint"] not in (eflesh.fingerprint, anyskin.fingerprint)
    with pytest.raises(BoardMismatchError, match=r"the model is of board 'eflesh' .* and the dataset of board "
                                                 r"'anyskin-5' .*: the LSB sizes \[2.4, 3.872\] against"):
        check_same_board("the model", before, "the dataset", anyskin.record)
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
                          "chip 0's axis turn")
    assert not (tmp_path / "ev").exists()


def _with_board(model: Path, out: Path, record: dict | None) -> Path:
    """A copy of ``model`` whose metadata stores board ``record`` (None: names its board only, as models exported
    before records did)."""
    onnx = pytest.importorskip("onnx")
    import json

    from tactile_manip.perception.reconstruct import METADATA_KEY

    proto = onnx.load(str(model))
    entry = next(p for p in proto.metadata_props if p.key == METADATA_KEY)
    meta = json.loads(entry.value)
    meta.pop("board", None)
    entry.value = json.dumps(meta if record is None else {**meta, "board": record})
    onnx.save(proto, str(out))
    return out


def test_a_model_of_a_shipped_boards_former_file_refuses_to_load(tmp_path, capsys):
    """A shipped board's file changed (eflesh's chip axes): a model trained on it before reads the chips as they
    were, so it refuses to load, naming both fingerprints and how to retrain it; the shipped models load."""
    pytest.importorskip("onnxruntime")
    from tactile_manip.perception.contact import ContactEstimator
    from tactile_manip.perception.reconstruct import OnnxReconstructor, recipe_of

    models = BOARDS.parents[1] / "models"
    shipped = ContactEstimator(models / "contact_eflesh.onnx")
    assert shipped.metadata["board"]["fingerprint"] == load_board("eflesh").fingerprint
    for name in ("contact_supermag", "contact_anyskin5"):
        ContactEstimator(models / f"{name}.onnx")
    OnnxReconstructor(models / "supermag.onnx")
    before = record_of_name("eflesh")  # the eflesh file before its chips' axes were fitted
    stale = _with_board(models / "contact_eflesh.onnx", tmp_path / "stale.onnx", before)
    named = _with_board(models / "contact_eflesh.onnx", tmp_path / "named.onnx", None)
    for model in (stale, named):
        with pytest.raises(BoardMismatchError) as refused:
            ContactEstimator(model)
        message = str(refused.value)
        assert "\n" not in message and f"({before['fingerprint']})" in message
        for needle in ("trained on board 'eflesh'", f"now reads as {load_board('eflesh').fingerprint}",
                       "chip 0's axis turn differ", "retrain it by its recipe"):
            assert needle in message, (needle, message)
    # a copy with no card beside it points at the training config it stores; the shipped file at its card
    assert "retrain it by its recipe (the train_config its metadata stores)" in message
    assert recipe_of(models / "contact_eflesh.onnx") == str(models / "contact_eflesh.md")
    # evaluate refuses it in one line and writes nothing
    data = tmp_path / "eflesh.npz"
    assert main(["simulate", "--board", "eflesh", "--presses", "4", "--out", str(data)]) == 0
    capsys.readouterr()
    assert main(["evaluate", "--data", str(data), "--model", f"e={stale}", "--out", str(tmp_path / "ev")]) == 2
    assert_one_line_error(capsys.readouterr().err, "evaluate", "trained on board 'eflesh'", before["fingerprint"],
                          load_board("eflesh").fingerprint, "retrain it by its recipe")
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


def test_a_chip_place_half_unknown_is_named_as_such(tmp_path):
    text = (BOARDS / "eflesh.toml").read_text().replace('name = "eflesh"', 'name = "mine"')
    text = text.replace("position_mm = [0.0, 0.0]", "position_mm = [nan, 0.0]", 1)
    with pytest.raises(ConfigError, match=r"position_mm must be two finite numbers .* got \[nan, 0.0\]"):
        load_board(_board_file(tmp_path, "half.toml", text))


def test_export_refuses_data_of_another_reading_grid_before_any_work(contact_model_files, tmp_path, capsys):
    """A checkpoint of a (3, 3) board handed (4, 4) readings: one line naming both shapes, nothing written."""
    pytest.importorskip("torch")
    _, run, _ = contact_model_files
    data = tmp_path / "supermag.npz"
    assert main(["simulate", "--board", "supermag-4x4", "--presses", "4", "--out", str(data)]) == 0
    capsys.readouterr()
    out = tmp_path / "m.onnx"
    assert main(["export", "--checkpoint", str(run / "best.pt"), "--data", str(data), "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "export", "holds (4, 4, 3) readings", "reads (3, 3, 3)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["supermag.npz"]
