"""The registry of model kinds: each entry's verbs resolve, and an unknown kind in a config or a checkpoint is one
line naming the file and the known kinds, before any work."""

import importlib

import pytest
from checks import TORCH_MISSING, assert_one_line_error

from tactile_manip.cli import main
from tactile_manip.errors import ConfigError
from tactile_manip.learning.kinds import DEFAULT_KIND, KINDS, ModelKind, kind_of_config, model_kind


def test_the_registry_holds_each_model_once_and_its_verbs_resolve():
    assert list(KINDS) == ["cvae", "angle_head", "contact"] and DEFAULT_KIND in KINDS
    for name, kind in KINDS.items():
        assert kind.name == name and kind.description and "\n" not in kind.description
        for target in (kind.train, kind.export):
            module, _, function = target.partition(":")
            assert module.startswith(f"tactile_manip.learning.{name}."), target  # each model's folder holds its own
            assert callable(getattr(importlib.import_module(module), function)), target


def test_an_entry_names_its_functions_as_module_and_function():
    with pytest.raises(ValueError, match="train must be 'module:function'"):
        ModelKind("x", "a model", train="tactile_manip.learning.x.verbs", export="m:f")


def test_an_unknown_kind_names_the_source_and_the_known_kinds(tmp_path):
    with pytest.raises(ConfigError, match=r"^unknown model kind 'foo'; the known kinds: cvae, angle_head, contact$"):
        model_kind("foo")
    config = tmp_path / "foo.toml"
    config.write_text('kind = "foo"\nepochs = 1\n')
    with pytest.raises(ConfigError, match=rf"^{config}: unknown model kind 'foo'"):
        kind_of_config(config)
    (tmp_path / "plain.toml").write_text("epochs = 1\n")
    assert kind_of_config(tmp_path / "plain.toml") is KINDS["cvae"]
    assert kind_of_config(tmp_path / "missing.toml") is KINDS["cvae"]  # the loader names a missing file


def test_train_refuses_a_config_of_an_unknown_kind_in_one_line(tmp_path, capsys):
    config = tmp_path / "foo.toml"
    config.write_text('kind = "foo"\nepochs = 1\n')
    out = tmp_path / "run"
    assert main(["train", "--config", str(config), "--data", str(tmp_path / "d.npz"), "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", str(config), "unknown model kind 'foo'",
                          "cvae, angle_head, contact")
    assert not out.exists()


def test_export_refuses_a_checkpoint_of_an_unknown_kind_in_one_line(tmp_path, capsys):
    torch = pytest.importorskip("torch", reason=TORCH_MISSING)
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    checkpoint = tmp_path / "best.pt"
    torch.save({"kind": "foo", "model": {}, "model_config": {}, "input": {}}, checkpoint)
    for verb in (["export"], ["export-model"]):
        assert main([*verb, "--checkpoint", str(checkpoint), "--out", str(tmp_path / "m.onnx")]) == 2
        assert_one_line_error(capsys.readouterr().err, verb[0], str(checkpoint), "unknown model kind 'foo'",
                              "cvae, angle_head, contact")
    assert not (tmp_path / "m.onnx").exists()
