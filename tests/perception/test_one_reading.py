"""The one-reading graph an export carries beside its main graph: used for one reading and one sample, the same
images as the main graph, refused when it does not belong to its file, absent in older files."""

from __future__ import annotations

import base64
from pathlib import Path

import numpy as np
import pytest
from checks import REFERENCE_MODELS_DIR

from tactile_manip.perception.one_reading import ONE_READING_KEY, remove_from
from tactile_manip.perception.reconstruct import ModelFileError, OnnxReconstructor
from tactile_manip.shipped import shipped_model

onnx = pytest.importorskip("onnx")


def _readings(model, n: int = 5) -> np.ndarray:
    return np.random.default_rng(3).normal(0.0, 120.0, (n, *model.taxels)).astype(np.float32)


def _with_one_reading(src: Path, dst: Path, value: str | None) -> Path:
    """A copy of ``src`` whose one-reading entry is ``value`` (None: removed, as in files exported before it)."""
    proto = onnx.load(str(src))
    remove_from(proto)
    if value is not None:
        entry = proto.metadata_props.add()
        entry.key, entry.value = ONE_READING_KEY, value
    onnx.save(proto, str(dst))
    return dst


def _one_reading_graph(path: Path):
    value = {p.key: p.value for p in onnx.load(str(path)).metadata_props}[ONE_READING_KEY]
    return onnx.load_from_string(base64.b64decode(value))


def test_an_export_carries_a_one_reading_graph_that_gives_the_main_graphs_images(onnx_4x4, onnx_5x6) -> None:
    for model in (onnx_4x4, onnx_5x6):
        graph = _one_reading_graph(model.path)
        assert [i.name for i in graph.graph.input] == ["field_ut"]
        assert [d.dim_value for d in graph.graph.input[0].type.tensor_type.shape.dim] == [1, *model.taxels]
        assert model.metadata["one_reading"]["output"]["shape"] == [1, *model.image_hw]
        fast, main = OnnxReconstructor(model.path), OnnxReconstructor(model.path, one_reading_graph=False)
        assert fast.one_reading and not main.one_reading
        readings = _readings(model)
        batch = main.reconstruct_batch(readings)
        assert batch.max() > 0  # images that depend on the reading, not all-zero
        for reading, expected in zip(readings, batch):
            got = fast.reconstruct(reading)
            assert got.spread_mm is None
            np.testing.assert_allclose(got.depth_mm, expected, rtol=0, atol=1e-5)
            np.testing.assert_allclose(main.reconstruct(reading).depth_mm, expected, rtol=0, atol=1e-5)
        # single readings and a batch of one run it (not the main graph); batches and prior samples do not
        calls = []
        one = fast._one

        class Spy:
            def run(self, *args, **kwargs):
                calls.append(len(args[1]["field_ut"]))
                return one.run(*args, **kwargs)

        fast._one = Spy()
        fast.reconstruct(readings[0])
        np.testing.assert_allclose(fast.reconstruct_many(readings[:1])[0].depth_mm, batch[0], rtol=0, atol=1e-5)
        fast.reconstruct_batch(readings)
        assert calls == [1, 1]
        assert not OnnxReconstructor(model.path, samples=3).one_reading
        # two sessions with their own spinning thread pools would fight over the cores: one thread only
        assert not OnnxReconstructor(model.path, threads=2).one_reading


def test_a_file_exported_before_the_one_reading_graph_runs_its_main_graph(onnx_4x4, tmp_path) -> None:
    old = OnnxReconstructor(_with_one_reading(onnx_4x4.path, tmp_path / "old.onnx", None))
    assert not old.one_reading
    readings = _readings(onnx_4x4, 2)
    expected = OnnxReconstructor(onnx_4x4.path, one_reading_graph=False).reconstruct_batch(readings)
    np.testing.assert_array_equal(old.reconstruct(readings[0]).depth_mm, expected[0])


def _perturbed(path: Path) -> str:
    """The file's one-reading graph with one weight changed: the right signature, other images."""
    graph = _one_reading_graph(path)
    from onnx import numpy_helper

    biggest = max(graph.graph.initializer, key=lambda t: int(np.prod(t.dims)))
    values = numpy_helper.to_array(biggest).copy()
    values.flat[: values.size // 2] += 1.0
    biggest.CopyFrom(numpy_helper.from_array(values, biggest.name))
    return base64.b64encode(graph.SerializeToString()).decode()


@pytest.mark.parametrize("case, message", [
    ("other model", r"maps \[\('field_ut', \[1, 5, 6, 3\]"),
    ("other weights", "differs from the main graph by"),
    ("not base64", "not valid base64"),
    ("not onnx", "onnxruntime cannot load its one-reading graph"),
])
def test_a_one_reading_graph_that_does_not_belong_to_its_file_is_refused(onnx_4x4, onnx_5x6, tmp_path, case,
                                                                           message) -> None:
    value = {"other model": lambda: {p.key: p.value for p in onnx.load(str(onnx_5x6.path)).metadata_props}[ONE_READING_KEY],
             "other weights": lambda: _perturbed(onnx_4x4.path),
             "not base64": lambda: "this is not base64 at all!",
             "not onnx": lambda: base64.b64encode(b"\x00 no graph here").decode()}[case]()
    path = _with_one_reading(onnx_4x4.path, tmp_path / "tampered.onnx", value)
    with pytest.raises(ModelFileError, match=message) as err:
        OnnxReconstructor(path)
    text = str(err.value)
    assert str(path) in text and "tactile-manip export" in text
    # the main graph alone still loads, for those who want it
    assert not OnnxReconstructor(path, one_reading_graph=False).one_reading


def test_shipped_models_carry_their_one_reading_graph() -> None:
    pytest.importorskip("onnxruntime")
    for path in (shipped_model("supermag"), REFERENCE_MODELS_DIR / "supermag_fast.onnx",
                 REFERENCE_MODELS_DIR / "supermag_robust.onnx"):
        assert OnnxReconstructor(path).one_reading, path  # one pass: the runtime default
    # the default model's file averages each image over the reading's 4 turns: one batch of copies, not the graph
    assert not OnnxReconstructor(shipped_model("supermag"), image_symmetry="stored").one_reading

