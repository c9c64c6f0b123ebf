"""benchmarks/bench_contact.py: what its report holds (no speed is asserted: the figures are the machine's)."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

pytest.importorskip("onnxruntime", reason="the contact estimator runs onnxruntime")

from benchmarks import bench_contact  # noqa: E402
from tactile_manip.data import load_dataset  # noqa: E402
from tactile_manip.perception.contact import ContactEstimator  # noqa: E402
from tactile_manip.perception.contact_context import context_windows  # noqa: E402


def test_a_case_reports_every_call_and_the_error_of_the_model_on_its_test_windows(contact_model_files) -> None:
    data_path, _, model_path = contact_model_files
    case = bench_contact.bench_case(str(model_path), str(data_path), repeats=3, budget_ms=0.2)
    data = load_dataset(data_path)
    test = data.indices("test")
    assert case["readings"] == len(test) and case["calls"] == 3 * len(test) and case["passes"] == 3
    assert 0 < case["p50_ms"] <= case["p99_ms"] <= case["max_ms"]
    assert case["p99_quietest_pass_ms"] <= case["p99_median_pass_ms"] <= case["max_ms"]
    assert 0 < case["cpu_p50_ms"] <= case["cpu_p99_ms"] and 0 <= case["over_budget_share"] <= 1
    assert case["graph_p50_ms"] > 0 and case["session_run_p50_ms"] > 0
    est = ContactEstimator(model_path)
    # the test readings are a stream of their own: the first ones have no training readings as context
    windows = context_windows(data.readings[test], frames=3, max_gap_s=1.0, time_s=data.extra("time_s")[test])
    mean, _ = est.session.run(None, {"field_ut": windows})
    force = data.target("force_n")[test]
    assert case["rmse"]["force_n"] == pytest.approx(np.sqrt(np.mean((mean[:, 2] - force) ** 2)), rel=1e-5)
    assert "position_rmse_mm" in case and case["context_frames"] == 3


def test_the_command_writes_the_json_and_the_markdown_beside_it(tmp_path, monkeypatch, contact_model_files,
                                                                capsys) -> None:
    data_path, _, model_path = contact_model_files
    out = tmp_path / "latency.json"
    monkeypatch.setattr(sys, "argv", ["bench_contact", "--case", f"tiny={model_path}:{data_path}", "--repeats", "1",
                                      "--period-ms", "0.5", "--out", str(out)])
    bench_contact.main()
    report = json.loads(out.read_text())
    assert report["period_ms"] == 0.5 and report["cases"]["tiny"]["calls"] == report["cases"]["tiny"]["readings"]
    table = out.with_suffix(".md").read_text()
    assert "| tiny | 3 |" in table and "one call per 0.5 ms" in table
    assert table.strip() in capsys.readouterr().out


def test_a_malformed_case_is_one_usage_error(monkeypatch) -> None:
    monkeypatch.setattr(sys, "argv", ["bench_contact", "--case", "no-model-here"])
    with pytest.raises(SystemExit) as stop:
        bench_contact.main()
    assert stop.value.code == 2
