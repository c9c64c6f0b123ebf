"""``tactile-manip collect``: one-line errors, finalize, and the whole path on the emulated MBTS and the
simulated camera: calibrate -> collect (jitter, drops, bit flips) -> train -> export -> evaluate, unconverted."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest
from checks import TORCH_MISSING, assert_one_line_error

from tactile_manip.cli import main
from tactile_manip.collection.pair_log import read_pair_log
from tactile_manip.data import load_dataset


def test_missing_calibration_is_one_line(tmp_path, capsys):
    assert main(["collect", "run", "--sim", "--calibration", str(tmp_path / "none.npz"),
                 "--out", str(tmp_path / "d.npz")]) == 2
    assert_one_line_error(capsys.readouterr().err, "collect", "VBTS calibration not found", "collect calibrate")


@pytest.mark.skipif(importlib.util.find_spec("cv2") is not None, reason="opencv is installed here")
def test_a_real_camera_without_opencv_names_the_extra(tmp_path, capsys):
    assert main(["collect", "calibrate", "--camera", "0", "--corners", "489,72 151,66 146,411 494,413",
                 "--ball-radius-mm", "4", "--out", str(tmp_path / "c.npz")]) == 2
    assert_one_line_error(capsys.readouterr().err, "collect", 'pip install -e ".[camera]"')


def test_bad_corners_are_refused_by_the_parser(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["collect", "calibrate", "--camera", "0", "--corners", "1,2 3,4", "--ball-radius-mm", "4",
              "--out", str(tmp_path / "c.npz")])
    assert "four 'u,v' pixel pairs" in capsys.readouterr().err


def test_calibrate_sim_writes_a_calibration_and_reports_its_error(tmp_path, capsys):
    out = tmp_path / "cal.npz"
    assert main(["collect", "calibrate", "--sim", "--ball-radius-mm", "4", "--frames", "6", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "table vs the simulated camera's true table" in text and out.is_file()
    assert main(["collect", "calibrate", "--sim", "--ball-radius-mm", "4", "--out", str(out)]) == 2  # no --force
    assert_one_line_error(capsys.readouterr().err, "collect", "exists; pass --force")


def test_finalize_merges_logs_and_tolerates_a_torn_tail(tmp_path, capsys, write_log):
    a = write_log(tmp_path / "a.tmpairs", ["allen_key"] * 10)
    b = write_log(tmp_path / "b.tmpairs", ["hex_bar"] * 4)
    b.write_bytes(b.read_bytes()[:-30])
    out = tmp_path / "d.npz"
    assert main(["collect", "finalize", str(a), str(b), "--out", str(out), "--test-objects", "hex_bar"]) == 0
    assert "torn tail" in capsys.readouterr().out
    data = load_dataset(out)
    assert len(data) == 13 and len(data.indices("test")) == 3


@pytest.mark.slow
def test_collect_on_the_emulator_then_train_and_evaluate_without_conversion(tmp_path, capsys):
    pytest.importorskip("torch", reason=TORCH_MISSING)
    cal, data, log = tmp_path / "cal.npz", tmp_path / "pairs.npz", tmp_path / "pairs.tmpairs"
    assert main(["collect", "calibrate", "--sim", "--ball-radius-mm", "4", "--frames", "6", "--out", str(cal)]) == 0
    assert main(["collect", "run", "--sim", "--calibration", str(cal), "--out", str(data), "--presses", "6",
                 "--objects", "allen_key,letter_r,hex_bar", "--test-objects", "hex_bar", "--pairs-per-press", "2",
                 "--val-fraction", "0.25", "--camera-jitter-ms", "3", "--camera-drop-rate", "0.2",
                 "--bit-flip-rate", "0.05", "--seed", "3"]) == 0
    printed = capsys.readouterr().out
    # synchronization: never beyond the 5 ms tolerance, by timestamps and by the simulation's true times
    pairs = read_pair_log(log)
    start = pairs.header["script_start_host_s"]
    dt = np.array([p.info["dt_s"] for p in pairs.pairs])
    true = np.array([p.info["t_exposure_s"] - (start + p.info["t_device_field_s"]) for p in pairs.pairs])
    print(f"\n{printed}pairs {len(dt)}: |dt| max {np.abs(dt).max() * 1e3:.2f} ms; true exposure-to-MBTS-sample "
          f"offset max {np.abs(true).max() * 1e3:.2f} ms")
    assert len(dt) >= 10 and np.abs(dt).max() <= 0.005 and np.abs(true).max() <= 0.006
    # the dataset goes to the CVAE commands as it is
    d = load_dataset(data)
    assert {s: len(d.indices(s)) > 0 for s in ("train", "val", "test")} == {"train": True, "val": True, "test": True}
    assert d.depth_mm().max() > 0.8  # the objects were seen
    tiny = tmp_path / "tiny.toml"
    tiny.write_text('preset = "small"\nepochs = 1\nbatch_size = 4\nlr = 3e-3\nthreads = 1\n')
    assert main(["train", "--config", str(tiny), "--data", str(data), "--out", str(tmp_path / "run")]) == 0
    model = tmp_path / "m.onnx"
    assert main(["export", "--checkpoint", str(tmp_path / "run" / "best.pt"), "--out", str(model),
                 "--data", str(data)]) == 0
    assert main(["evaluate", "--data", str(data), "--model", f"Tiny={model}", "--out", str(tmp_path / "eval")]) == 0
    results = json.loads((tmp_path / "eval" / "results.json").read_text())
    assert [r["method"] for r in results["results"]] == ["Bilinear", "Bicubic", "Tiny"]
