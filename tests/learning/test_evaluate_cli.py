"""train -> export -> evaluate through the CLI on a tiny dataset: the whole user path, end to end."""

import json

import pytest

pytest.importorskip("torch", reason="training tests need torch: pip install torch==2.13.0")

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
    err = capsys.readouterr().err
    assert "checkpoint not found" in err and err.count("\n") == 1


def test_evaluate_refuses_a_bad_model_argument(tiny_data, tmp_path, capsys):
    assert main(["evaluate", "--data", str(tiny_data), "--model", "no-equals-sign", "--out", str(tmp_path)]) == 2
    assert "LABEL=PATH" in capsys.readouterr().err


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
    err = capsys.readouterr().err
    assert "no training presses of no_such_object" in err
