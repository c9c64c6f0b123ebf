"""``tactile-manip bench`` end to end on a handful of readings: baselines and the shipped model."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from checks import assert_one_line_error

from tactile_manip.cli import main

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "experiments" / "model_variants" / "supermag_compact.onnx"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_bench_writes_report_json_and_plot_and_prints_the_table(bench_data, tmp_path, monkeypatch, capsys) -> None:
    pytest.importorskip("onnxruntime")
    monkeypatch.chdir(ROOT)  # the default model paths are relative to the repository root
    out = tmp_path / "bench"
    rc = main(["bench", "--out", str(out), "--quick", "--data", str(bench_data), "--candidates",
               "experiments/model_variants/bench.toml", "--methods", "bilinear,bicubic,compact", "--runtimes", "ort-1",
               "--trials", "1"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert printed.startswith("| method | runtime |") and "| compact | onnxruntime 1 thread |" in printed
    report = json.loads((out / "report.json").read_text())
    assert [(r["method"], r["runtime"]) for r in report["rows"]] == [
        ("bilinear", "numpy"), ("bicubic", "numpy"), ("compact", "onnxruntime 1 thread")]
    compact = report["rows"][2]
    # the training column comes from the run history shipped beside the model
    epochs_run = json.loads(SHIPPED.with_name("supermag_compact.history.json").read_text())["epochs_run"]
    assert compact["parameters"] == 1_411_050 and compact["training"] == f"{epochs_run} epochs"
    assert compact["psnr_db"] > report["rows"][0]["psnr_db"]  # the shipped model beats the baseline
    if report.get("trials"):
        assert compact["trials"]["n"] == 1
    else:
        assert any("roboticstoolbox" in n for n in report["notes"])
    assert report["settings"]["quick"] and report["machine"]["cpu_model"]
    md = (out / "report.md").read_text()
    assert "| compact | onnxruntime 1 thread |" in md and "Pareto front" in md
    assert (out / "pareto.png").read_bytes()[:8] == PNG_MAGIC


def test_a_bad_model_spec_is_a_one_line_error(capsys, tmp_path) -> None:
    assert main(["bench", "--out", str(tmp_path), "--model", "no-equals-sign"]) == 2
    line = assert_one_line_error(capsys.readouterr().err, "bench")
    assert line.startswith("tactile-manip bench: error: --model must be NAME=PATH"), line
