"""The shipped models are found from the package, whatever the working folder; the default is supermag.onnx, in
models/, which holds the shipped models only; the bench references are in experiments/model_variants/."""

import pytest

from tactile_manip.shipped import (DEFAULT_MODEL, REFERENCE_MODELS, SHIPPED_MODELS, model_folder, models_dir,
                                   shipped_model, variants_dir)


@pytest.mark.parametrize("name", sorted(SHIPPED_MODELS))
def test_shipped_model_resolves_from_any_folder(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = shipped_model(name)
    assert path.is_absolute() and path.is_file()
    assert path.parent == model_folder(name) and path.name == SHIPPED_MODELS[name]


def test_default_is_the_supermag_model_and_the_others_are_bench_references():
    assert shipped_model().name == "supermag.onnx" == SHIPPED_MODELS[DEFAULT_MODEL]
    assert set(REFERENCE_MODELS) == set(SHIPPED_MODELS) - {DEFAULT_MODEL, "contact"} == {"fast", "robust", "compact"}
    assert shipped_model("contact") == models_dir() / "contact_supermag.onnx"


def test_the_default_model_carries_an_angle_head():
    pytest.importorskip("onnxruntime", reason="opening the model's graphs needs onnxruntime (extra 'onnx')")
    from tactile_manip.perception import load_reconstructor

    assert load_reconstructor(shipped_model()).angle_head is not None
    assert load_reconstructor(shipped_model("robust")).angle_head is None


def test_models_holds_the_shipped_models_only_and_the_references_are_research_records():
    onnx = sorted(p.name for p in models_dir().glob("*.onnx"))
    assert len(onnx) <= 2, onnx
    assert shipped_model().parent == models_dir()
    for name in ("fast", "robust", "compact"):
        path = shipped_model(name)
        assert path.is_file() and path.parent == variants_dir()
        assert path.parent.parent.name == "experiments" and path.parent.name == "model_variants"
        assert not (models_dir() / path.name).exists()


def test_unknown_name_is_refused():
    with pytest.raises(ValueError,
                       match="unknown shipped model 'tiny': expected one of supermag, contact, fast, robust, compact"):
        shipped_model("tiny")


def test_missing_models_folder_says_where_they_are(monkeypatch, tmp_path):
    monkeypatch.setattr("tactile_manip.shipped.models_dir", lambda: tmp_path)
    with pytest.raises(FileNotFoundError, match="source checkout's models/ folder"):
        shipped_model()


def test_missing_variants_folder_says_where_they_are(monkeypatch, tmp_path):
    monkeypatch.setattr("tactile_manip.shipped.variants_dir", lambda: tmp_path)
    with pytest.raises(FileNotFoundError, match="source checkout's experiments/model_variants/ folder"):
        shipped_model("fast")
