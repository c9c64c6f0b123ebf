"""An export that fails leaves no half-written file, and no loader takes one: a ``.partial`` file is what export
writes while it checks the model, and is renamed only once the check passed."""

from __future__ import annotations

import shutil

import pytest
from checks import assert_one_line_error

from tactile_manip.cli import main
from tactile_manip.perception.model_metadata import ModelFileError


def test_loaders_refuse_an_unfinished_export(contact_model_files, tmp_path, capsys):
    pytest.importorskip("onnxruntime")
    from tactile_manip.perception.contact import ContactEstimator
    from tactile_manip.perception.reconstruct import OnnxReconstructor
    from tactile_manip.shipped import shipped_model

    data, _, model = contact_model_files
    partial = tmp_path / "contact.onnx.partial"
    shutil.copy(model, partial)
    with pytest.raises(ModelFileError, match="an unfinished export"):
        ContactEstimator(partial)
    image = tmp_path / "supermag.onnx.partial"
    shutil.copy(shipped_model(), image)
    with pytest.raises(ModelFileError, match="an unfinished export"):
        OnnxReconstructor(image)
    assert main(["evaluate", "--data", str(data), "--model", f"p={partial}", "--out", str(tmp_path / "e")]) == 2
    assert_one_line_error(capsys.readouterr().err, "evaluate", "unfinished export")
    assert not (tmp_path / "e").exists()


def test_a_failed_export_leaves_no_partial_file(contact_model_files, tmp_path, monkeypatch):
    pytest.importorskip("torch")
    pytest.importorskip("onnx")
    from tactile_manip.learning.contact import export as contact_export

    _, run, _ = contact_model_files

    def broken_check(*args, **kwargs):
        raise contact_export.ExportError("ONNX output differs from torch")

    monkeypatch.setattr(contact_export, "check_contact_parity", broken_check)
    out = tmp_path / "m.onnx"
    with pytest.raises(contact_export.ExportError):
        contact_export.export_contact_onnx(run / "best.pt", out)
    assert sorted(p.name for p in tmp_path.iterdir()) == []
