"""The shipped models are found from the package, whatever the working folder; the default is supermag.onnx, in
models/, which holds the shipped models only."""

import pytest

from tactile_manip.shipped import DEFAULT_MODEL, SHIPPED_MODELS, models_dir, shipped_model


@pytest.mark.parametrize("name", sorted(SHIPPED_MODELS))
def test_shipped_model_resolves_from_any_folder(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = shipped_model(name)
    assert path.is_absolute() and path.is_file()
    assert path.parent == models_dir() and path.name == SHIPPED_MODELS[name]


def test_default_is_the_supermag_model_beside_its_contact_model():
    assert shipped_model().name == "supermag.onnx" == SHIPPED_MODELS[DEFAULT_MODEL]
    assert set(SHIPPED_MODELS) == {DEFAULT_MODEL, "contact", "contact_eflesh", "contact_anyskin5"}
    assert shipped_model("contact") == models_dir() / "contact_supermag.onnx"


def test_the_default_model_carries_an_angle_head():
    pytest.importorskip("onnxruntime", reason="opening the model's graphs needs onnxruntime (extra 'onnx')")
    from tactile_manip.perception import load_reconstructor

    assert load_reconstructor(shipped_model()).angle_head is not None
    references = models_dir().parent / "experiments" / "model_variants"
    assert load_reconstructor(references / "supermag_robust.onnx").angle_head is None


def test_models_holds_the_shipped_models_only():
    onnx = sorted(p.name for p in models_dir().glob("*.onnx"))
    assert onnx == sorted(SHIPPED_MODELS.values())


def test_unknown_name_is_refused():
    with pytest.raises(ValueError,
                       match="unknown shipped model 'tiny': expected one of supermag, contact"):
        shipped_model("tiny")


def test_missing_models_folder_says_where_they_are(monkeypatch, tmp_path):
    monkeypatch.setattr("tactile_manip.shipped.models_dir", lambda: tmp_path)
    with pytest.raises(FileNotFoundError, match="source checkout's models/ folder"):
        shipped_model()
