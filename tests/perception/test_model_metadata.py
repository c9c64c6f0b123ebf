"""Model files whose metadata was edited are refused at load, naming the file and the field: targets renamed
against their units or the graph's outputs, a board layout of another grid, a context that is not the graph's."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from checks import assert_one_line_error, assert_one_line_message

from tactile_manip.perception.model_metadata import check_metadata
from tactile_manip.perception.reconstruct import METADATA_KEY, ModelFileError, OnnxReconstructor, read_metadata

onnx = pytest.importorskip("onnx", reason="rewriting a model's metadata needs onnx (pip install -e '.[train]')")
pytest.importorskip("onnxruntime", reason="loading models needs onnxruntime")

from tactile_manip.perception.contact import ContactEstimator  # noqa: E402

MODELS = Path(__file__).resolve().parents[2] / "models"
VARIANTS = MODELS.parent / "experiments" / "model_variants"  # the reference models kept for the bench
CONTACT = MODELS / "contact_supermag.onnx"
IMAGE = MODELS / "supermag.onnx"


def _edited(source: Path, out: Path, edit) -> Path:
    """``source`` with ``edit(meta)`` applied to its tactile_manip metadata, saved as ``out``."""
    proto = onnx.load(str(source))
    for prop in proto.metadata_props:
        if prop.key == METADATA_KEY:
            meta = json.loads(prop.value)
            edit(meta)
            prop.value = json.dumps(meta)
    onnx.save(proto, str(out))
    return out


def _set(path: str, value):
    """An edit setting the dotted ``path`` of the metadata to ``value``."""
    def edit(meta: dict) -> None:
        *parents, last = path.split(".")
        node = meta
        for key in parents:
            node = node[key]
        node[last] = value
    return edit


def _swap_targets(meta: dict) -> None:
    names = meta["targets"]["names"]
    names[0], names[3] = names[3], names[0]  # force_n where x_mm was; the units stay in their order


def _drop_a_target(meta: dict) -> None:
    meta["targets"] = {"names": meta["targets"]["names"][:4], "units": meta["targets"]["units"][:4]}
    meta["output"]["shape"] = ["batch", 4]


def _seven_frames(meta: dict) -> None:
    meta["input"]["shape"][1] = 7
    meta["context"]["frames"] = 7


@pytest.mark.parametrize("edit, field, problem", [
    (_swap_targets, "targets.units[0]", "is 'mm', but target 'force_n' is in 'N'"),
    (_set("targets.units", ["mm", "mm", "mm", "N"]), "targets.units", "has 4 units for 5 targets"),
    (_drop_a_target, "targets.names", "names 4 targets, but the graph's output mean ['batch', 5] gives 5"),
    (_set("board_layout", "anyskin-5"), "board_layout", "a 3x3 reading grid, but the input takes 4x4"),
    (_set("context.frames", 7), "context.frames", "is 7, but input.shape[1] (the frames) is 1"),
    (_set("context.frames", "three"), "context.frames", "is 'three', not an integer"),
    (_seven_frames, "context.frames / input.shape[1]", "is 7, but the graph's input field_ut"),
    (_set("context.max_gap_s", "1 s"), "context.max_gap_s", "not a number"),
    (_set("targets.names", "x_mm"), "targets.names", "not a list"),
    (_set("input.shape", ["batch", 1, 4, 4.5, 3]), "input.shape[3]", "is 4.5, not an integer"),
])
def test_a_contact_model_with_edited_metadata_is_refused_naming_the_field(tmp_path, edit, field, problem):
    path = _edited(CONTACT, tmp_path / "edited.onnx", edit)
    with pytest.raises(ModelFileError) as e:
        ContactEstimator(path)
    assert_one_line_message(str(e.value), str(path), f"metadata field {field} ", problem)


@pytest.mark.parametrize("edit, field, problem", [
    (_set("board_layout", "anyskin-5"), "board_layout", "a 3x3 reading grid, but the input takes 4x4"),
    (_set("board_layout", "grid-5x6"), "board_layout", "a 5x6 reading grid"),
    (_set("output.pixel_mm", "0.1"), "output.pixel_mm", "not a number"),
    (_set("noise.shape", ["batch", "samples", "32"]), "noise.shape[2]", "not an integer"),
    (_set("input.shape", ["batch", 4, 4]), "input.shape", "not [batch, rows, cols, channels]"),
])
def test_an_image_model_with_edited_metadata_is_refused_naming_the_field(tmp_path, edit, field, problem):
    path = _edited(IMAGE, tmp_path / "edited.onnx", edit)
    with pytest.raises(ModelFileError) as e:
        OnnxReconstructor(path)
    assert_one_line_message(str(e.value), str(path), f"metadata field {field} ", problem)


def test_an_image_loader_given_a_contact_model_says_what_it_is():
    with pytest.raises(ModelFileError, match="a contact model, not an image model: load it with .*ContactEstimator"):
        OnnxReconstructor(CONTACT)


def test_every_shipped_model_passes_and_the_metadata_alone_is_checked_on_read(tmp_path):
    for path in sorted([*MODELS.glob("*.onnx"), *VARIANTS.glob("*.onnx")]):
        read_metadata(path)
    path = _edited(CONTACT, tmp_path / "edited.onnx", _set("context.frames", "three"))
    with pytest.raises(ModelFileError, match="context.frames is 'three'"):
        read_metadata(path)
    with pytest.raises(ModelFileError, match=r"x\.onnx: metadata field \(the whole\) is a list"):
        check_metadata([], path="x.onnx")


def test_evaluate_with_an_edited_contact_model_is_one_line(tmp_path, labelled_presses, capsys):
    from tactile_manip.cli import main
    from tactile_manip.data import save_dataset

    data = save_dataset(tmp_path / "d.npz", labelled_presses(60))
    path = _edited(CONTACT, tmp_path / "swapped.onnx", _swap_targets)
    out = tmp_path / "eval"
    assert main(["evaluate", "--data", str(data), "--model", f"C={path}", "--no-baselines", "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "evaluate", str(path), "targets.units[0]")
    assert not (out / "results.json").exists()
