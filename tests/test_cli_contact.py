"""The contact workflow at the command line: train (kind = "contact"), export, evaluate on labelled presses."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactile_manip.cli import main

pytest.importorskip("onnxruntime", reason="evaluating exported models needs onnxruntime")


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_evaluate_writes_table_results_and_plot_with_baselines_and_sigma(contact_model_files, tmp_path,
                                                                         capsys) -> None:
    data_path, _, model_path = contact_model_files
    out = tmp_path / "ev"
    assert main(["evaluate", "--data", str(data_path), "--model", f"ours={model_path}", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "| ours |" in printed and "| MLP |" in printed and "RMSE 2-D mm" in printed
    results = json.loads((out / "results.json").read_text())
    methods = results["methods"]
    assert set(methods) == {"ours", "Linear", "kNN", "MLP"}
    ours = methods["ours"]
    assert set(ours["rmse"]) == set(ours["mae"]) == {"x_mm", "y_mm", "force_n"}
    assert ours["position_rmse_mm"] == pytest.approx(np.hypot(ours["rmse"]["x_mm"], ours["rmse"]["y_mm"]), rel=1e-6)
    assert 0 <= ours["within_1_sigma"]["all"] <= ours["within_2_sigma"]["all"] <= 1
    assert "within_1_sigma" not in methods["Linear"]
    assert ours["n"] == 120 and sum(b["n"] for b in ours["force_bands"]) == 120
    assert (out / "contact.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "table.md").read_text().startswith("| method |")


def test_evaluate_refuses_a_model_of_other_targets_and_a_missing_model(contact_model_files, tmp_path, capsys,
                                                                        labelled_presses) -> None:
    import dataclasses

    from tactile_manip.data import save_dataset

    _, _, model_path = contact_model_files
    data = labelled_presses(100)
    force_only = dataclasses.replace(data, targets=data.targets[:, 2:], target_names=("force_n",))
    save_dataset(tmp_path / "force.npz", force_only)
    assert main(["evaluate", "--data", str(tmp_path / "force.npz"), "--model", f"ours={model_path}",
                 "--out", str(tmp_path / "ev")]) == 2
    assert "x_mm" in _one_line_error(capsys)
    assert not (tmp_path / "ev" / "results.json").exists()
    assert main(["evaluate", "--data", str(tmp_path / "force.npz"), "--model", f"ours={tmp_path / 'no.onnx'}",
                 "--out", str(tmp_path / "ev")]) == 2
    assert "no.onnx" in _one_line_error(capsys)


def test_train_with_the_contact_kind_writes_a_run_and_refuses_cvae_flags(contact_model_files, tmp_path,
                                                                         capsys) -> None:
    pytest.importorskip("torch", reason="training needs torch")
    data_path, _, _ = contact_model_files
    cfg = tmp_path / "tiny.toml"
    cfg.write_text('kind = "contact"\nhidden = 8\nmembers = 1\nepochs = 2\nthreads = 1\n')
    out = tmp_path / "run"
    assert main(["train", "--config", str(cfg), "--data", str(data_path), "--out", str(out)]) == 0
    assert "validation RMSE" in capsys.readouterr().out
    assert (out / "best.pt").is_file() and (out / "history.json").is_file()
    assert main(["train", "--config", str(cfg), "--data", str(data_path), "--out", str(tmp_path / "r2"),
                 "--init", str(out / "best.pt")]) == 2
    assert "--init" in _one_line_error(capsys)
