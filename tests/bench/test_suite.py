"""The report run on a handful of readings: the same figures as the evaluate command, skips, shared accuracy."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest
from checks import TORCH_MISSING

from tactile_manip.bench.accuracy import rod_scene
from tactile_manip.bench.candidates import ModelEntry
from tactile_manip.bench.suite import SHARE_TOLERANCE_MM, BenchSettings, run_bench
from tactile_manip.bench.timing import TimingBudget
from tactile_manip.evaluation.images import evaluate_methods
from tactile_manip.perception.reconstruct import load_reconstructor
from tactile_manip.data import load_dataset
from tactile_manip.trials.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]
DATASET_CONFIG = ROOT / "configs" / "dataset" / "supermag.toml"

TINY = BenchSettings(per_object=None, trials=0, parity_readings=4,
                     timing=TimingBudget(max_calls=5, min_calls=2, max_seconds=0.2, warmup=1, batch=8, batch_rounds=1))


def _bench(data, **kwargs):
    kwargs.setdefault("models", [])
    return run_bench(settings=TINY, data_path=data, dataset_config=DATASET_CONFIG, **kwargs)


def test_report_psnr_ssim_and_angles_are_those_of_the_evaluation_on_the_same_readings(bench_data) -> None:
    report = _bench(bench_data)
    data = load_dataset(bench_data)
    results, _ = evaluate_methods(data, {n: load_reconstructor(n) for n in ("bilinear", "bicubic")})
    assert [r["method"] for r in report["rows"]] == ["bilinear", "bicubic"]
    for row, ref in zip(report["rows"], results):
        assert row["psnr_db"] == ref.psnr_db[0] and row["ssim"] == ref.ssim[0]
        assert row["angle_p95_deg"] == ref.angle_error_deg["p95"]
        assert row["latency_calls"] >= 2 and row["throughput_rps"] > 0 and row["pose_p99_ms"] >= row["pose_p50_ms"]
    assert report["readings"]["readings"] == 7 and report["readings"]["rod_readings"] == 6
    assert report["machine"]["usable_cores"] >= 1 and report["libraries"]["numpy"]
    assert "during_run" in report["machine"] and report["seconds"] > 0


def test_readings_are_simulated_when_the_dataset_is_missing(tmp_path) -> None:
    report = run_bench(settings=dataclasses.replace(TINY, per_object=1), models=[], methods=["bilinear"],
                       data_path=tmp_path / "absent.npz", dataset_config=DATASET_CONFIG)
    assert "simulated test objects" in report["readings"]["source"] and "not found" in report["readings"]["note"]
    assert report["readings"]["readings"] == 7 and report["rows"][0]["psnr_db"] > 0


def test_a_missing_model_file_is_a_note_not_a_crash(bench_data, tmp_path) -> None:
    report = _bench(bench_data, models=[ModelEntry("ghost", tmp_path / "none.onnx")], baselines=("bilinear",))
    assert [r["method"] for r in report["rows"]] == ["bilinear"]
    assert any(n.startswith("ghost: skipped") and "none.onnx" in n for n in report["notes"])


def test_unknown_runtime_is_refused(bench_data) -> None:
    with pytest.raises(ValueError, match="unknown runtimes"):
        _bench(bench_data, runtimes=["gpu"])


def test_model_runtimes_share_accuracy_only_after_their_outputs_agree(bench_data, tiny_model) -> None:
    entry = ModelEntry("tiny", tiny_model, tiny_model.with_name("best.pt"), symmetrized=True)
    report = _bench(bench_data, models=[entry], baselines=())
    rows = {(r["method"], r["runtime"]): r for r in report["rows"]}
    first = rows[("tiny", "onnxruntime 1 thread")]
    assert first["accuracy_from"] == "own" and first["parameters"] > 0 and first["training"] == "1 epoch (config)"
    torch_row = rows[("tiny", "torch eager 1 thread")]
    assert torch_row["accuracy_from"] == "tiny onnxruntime 1 thread"
    assert 0 < torch_row["parity_max_abs_mm"] <= SHARE_TOLERANCE_MM  # real, non-zero outputs that agree
    assert torch_row["psnr_db"] == first["psnr_db"]
    int8 = rows[("tiny", "onnxruntime int8 1 thread")]
    assert int8["accuracy_from"] == "own" and int8["file_mb"] < first["file_mb"]
    sym = rows[("tiny_sym", "onnxruntime 1 thread")]
    assert sym["accuracy_from"] == "own" and sym["psnr_db"] != first["psnr_db"]
    assert ("tiny_sym", "torch eager 1 thread") not in rows


def test_the_built_in_trial_scene_is_the_shipped_one() -> None:
    """So `tactile-manip trials --config configs/scenes/reorient_sim.toml --trials N --methods M` reproduces it."""
    shipped = load_scene(ROOT / "configs" / "scenes" / "reorient_sim.toml")
    assert rod_scene(30) == dataclasses.replace(shipped, trials=30)


def test_importing_the_harness_pulls_in_no_heavy_package() -> None:
    probe = ("import sys, tactile_manip.bench.suite, tactile_manip.bench.report, tactile_manip.commands.bench\n"
             "print(sorted({m.split('.')[0] for m in sys.modules} & {'torch', 'onnxruntime', 'matplotlib', "
             "'roboticstoolbox'}))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_unknown_method_names_are_refused_before_anything_runs(bench_data) -> None:
    with pytest.raises(ValueError, match=r"unknown methods \['bilnear'\]"):
        _bench(bench_data, methods=["bilnear"])


def test_a_corrupt_model_file_is_a_note(bench_data, tmp_path) -> None:
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not a model")
    report = _bench(bench_data, models=[ModelEntry("bad", bad)], baselines=("bilinear",))
    assert [r["method"] for r in report["rows"]] == ["bilinear"]
    assert any(n.startswith("bad: skipped (ModelFileError") for n in report["notes"]), report["notes"]


def test_a_missing_preset_model_is_exported_untrained_for_latency_only(bench_data, tmp_path) -> None:
    pytest.importorskip("torch", reason=TORCH_MISSING)
    pytest.importorskip("onnx")
    entry = ModelEntry("unt", tmp_path / "missing.onnx", tmp_path / "no.pt", untrained_preset="small")
    report = _bench(bench_data, models=[entry], baselines=(), runtimes=["ort-1", "torch"])
    assert [r["runtime"] for r in report["rows"]] == ["onnxruntime 1 thread", "torch eager 1 thread"]
    for row in report["rows"]:
        assert row["untrained"] and row["training"] == "untrained" and row["latency_p50_ms"] > 0
        assert "psnr_db" not in row and row["accuracy_from"].startswith("n/a (untrained")
    assert any("untrained small model was exported for latency only" in n for n in report["notes"])
