"""train -> export -> evaluate through the CLI on a tiny dataset: the whole user path, end to end."""

import json

import pytest
from checks import TORCH_MISSING, assert_one_line_error

pytest.importorskip("torch", reason=TORCH_MISSING)

from tactile_manip.cli import main
from tactile_manip.perception.reconstruct import read_metadata


def test_train_export_evaluate_round_trip(tiny_data, tmp_path, capsys):
    cfg = tmp_path / "tiny.toml"
    cfg.write_text('preset = "small"\nepochs = 2\nbatch_size = 8\nlr = 3e-3\nthreads = 1\n')
    run = tmp_path / "run"
    assert main(["train", "--config", str(cfg), "--data", str(tiny_data), "--out", str(run)]) == 0
    model = tmp_path / "m.onnx"
    assert main(["export", "--checkpoint", str(run / "best.pt"), "--out", str(model), "--data", str(tiny_data),
                 "--card", str(tmp_path / "card.md")]) == 0
    meta = read_metadata(model)
    assert meta["training_data"]["fingerprint"] == meta["data_fingerprint"]
    assert 1 <= meta["training"]["epochs_run"] <= 2  # trained, so it goes into the gallery
    assert "SuperMag CVAE" in (tmp_path / "card.md").read_text()
    out = tmp_path / "eval"
    assert main(["evaluate", "--data", str(tiny_data), "--model", f"Tiny={model}", "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    methods = [r["method"] for r in results["results"]]
    assert methods == ["Bilinear", "Bicubic", "Tiny"]
    assert all(r["psnr_db_mean"] > 0 and -1 <= r["ssim_mean"] <= 1 for r in results["results"])
    assert results["psnr_data_range"] == 2.0 and results["image_unit"] == "mm"
    assert (out / "gallery.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| Tiny |" in (out / "table.md").read_text()
    assert "left out of the gallery" not in capsys.readouterr().out


def test_export_refuses_a_missing_checkpoint_in_one_line(tmp_path, capsys):
    assert main(["export", "--checkpoint", str(tmp_path / "none.pt"), "--out", str(tmp_path / "x.onnx")]) == 2
    assert_one_line_error(capsys.readouterr().err, "export", "checkpoint not found")


def test_evaluate_refuses_a_bad_model_argument(tiny_data, tmp_path, capsys):
    assert main(["evaluate", "--data", str(tiny_data), "--model", "no-equals-sign", "--out", str(tmp_path)]) == 2
    assert_one_line_error(capsys.readouterr().err, "evaluate", "LABEL=PATH")


def test_evaluate_fits_the_baselines_on_the_named_objects_only(tiny_data, tmp_path, capsys):
    from tactile_manip.data import load_dataset

    data = load_dataset(tiny_data)
    first = str(data.objects(data.indices("train"))[0])
    fits = {}
    for objects in ("", first):
        out = tmp_path / (objects or "all")
        assert main(["evaluate", "--data", str(tiny_data), "--out", str(out), "--baseline-objects", objects]) == 0
        fits[objects] = json.loads((out / "results.json").read_text())["baseline_fits"]["Bilinear"]
    assert fits[""]["gain_mm_per_ut"] != fits[first]["gain_mm_per_ut"]
    assert main(["evaluate", "--data", str(tiny_data), "--out", str(tmp_path / "x"),
                 "--baseline-objects", "no_such_object"]) == 2
    assert_one_line_error(capsys.readouterr().err, "evaluate", "no training presses of no_such_object")


def test_evaluation_breaks_down_by_force_band_and_sensor_draw(tmp_path):
    import numpy as np

    from tactile_manip.data import PairedDataset, depth_image_spec
    from tactile_manip.evaluation.images import evaluate_methods, markdown_table
    from tactile_manip.perception.reconstruct import BASELINES

    rng = np.random.default_rng(0)
    n = 40
    yy, xx = np.mgrid[0:40, 0:40]
    yaw = rng.uniform(-1.5, 1.5, n)
    images = np.stack([np.clip(1.0 - np.abs((xx - 20) * np.sin(a) + (yy - 20) * np.cos(a)) / 3, 0, None)
                       for a in yaw])  # bars through the centre at yaw a (row 0 at +y)
    force = np.linspace(2.0, 15.0, n).astype(np.float32)
    draws = rng.uniform(0.03, 0.055, (n, 2)).astype(np.float32)
    data = PairedDataset(
        readings=rng.normal(0, 50, (n, 4, 4, 3)).astype(np.float32), images=(images / 0.01).astype(np.uint8),
        split=np.array(["train"] * 10 + ["test"] * 30), image=depth_image_spec(0.5),
        object_index=np.zeros(n, np.int16), object_names=np.array(["cylinder_3mm"]),
        extras={"force_n": force, "pose": np.c_[np.zeros((n, 2)), yaw, np.zeros((n, 2))].astype(np.float32),
                "sensor_params": draws},
        provenance={"sensor_param_names": ["magnet.remanence_t", "chip.noise_z_ut"]})
    fit = BASELINES["bilinear"].fit(data.readings[:10], data.depth_mm(np.arange(10)))
    results, _ = evaluate_methods(data, {"Bilinear": fit})
    groups = results[0].per_group
    assert list(groups["force"]) == ["5-8 N", "8-11 N", "11-15 N"]  # the test split holds 5.3-15 N
    assert sum(g["count"] for g in groups["force"].values()) == 30
    assert sum(g["count"] for g in groups["magnet"].values()) == 30 and len(groups["chip noise"]) == 3
    assert 0.0 <= groups["force"]["8-11 N"]["angle_within_5_deg"] <= 1.0
    table = markdown_table(results)
    assert "| force |" in table and "| magnet |" in table and "(n 30)" not in table.splitlines()[2]
