"""Bring your own data through the CLI: import -> train (a few steps) -> export -> evaluate with baselines,
on small synthetic datasets shaped like two real public ones (a 41x72 one-channel capacitive pad with 82x144
contact fractions; a 4x4x3 per-sample-normalised taxel array with 40x40 grey images), and every bad input on
the way as one line naming the array, exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest
from checks import TORCH_MISSING, assert_one_line_error

pytest.importorskip("torch", reason=TORCH_MISSING)

from tactile_manip.cli import main
from tactile_manip.data import load_dataset
from tactile_manip.perception.reconstruct import read_metadata


def _blobs(n: int, grid: tuple[int, int], image: tuple[int, int], rng) -> tuple[np.ndarray, np.ndarray]:
    """Round contacts at random places; the reading is the contact seen through a coarse grid."""
    h, w = image
    yy, xx = np.mgrid[0:h, 0:w]
    images = np.empty((n, h, w), np.float32)
    for i in range(n):
        cy, cx, r = rng.uniform(0.25, 0.75) * h, rng.uniform(0.25, 0.75) * w, rng.uniform(0.08, 0.2) * min(h, w)
        images[i] = np.clip(1.2 - ((yy - cy) ** 2 + (xx - cx) ** 2) / (r * r), 0, 1)
    coarse = images.reshape(n, grid[0], h // grid[0], grid[1], w // grid[1]).mean(axis=(2, 4))
    return coarse, images


@pytest.fixture(scope="module")
def arrays(tmp_path_factory):
    rng = np.random.default_rng(0)
    folder = tmp_path_factory.mktemp("byo")
    # capacitive: one channel, 41x72 taxels, contact fractions 0..1 at 82x144, 8 participants as groups
    cap_r, cap_i = _blobs(48, (41, 72), (82, 144), rng)
    np.save(folder / "cap_r.npy", (100.0 + 5.0 * cap_r).astype(np.float32))  # pF around a 100 pF baseline
    np.save(folder / "cap_i.npy", cap_i)
    np.save(folder / "cap_g.npy", np.repeat(np.arange(8), 6))
    # Xela-like: 4x4x3 per-sample-normalised counts, 40x40 grey levels 0..255, as one npz of named arrays
    x_r, x_i = _blobs(48, (4, 4), (40, 40), rng)
    counts = np.stack([x_r, 0.5 * x_r, -x_r], axis=-1) + rng.normal(0, 0.01, (48, 4, 4, 3))
    counts /= np.abs(counts).max(axis=(1, 2, 3), keepdims=True)
    np.savez(folder / "xela.npz", readings=counts, images=np.rint(255 * x_i).astype(np.uint8),
             split=np.array(["train"] * 36 + ["val"] * 6 + ["test"] * 6))
    return folder


def _train_export_evaluate(data, folder, capsys) -> dict:
    cfg = folder / "tiny.toml"
    cfg.write_text('preset = "small"\nepochs = 2\nbatch_size = 8\nlr = 3e-3\nthreads = 1\n')
    run, model, out = folder / "run", folder / "m.onnx", folder / "eval"
    assert main(["train", "--config", str(cfg), "--data", str(data), "--out", str(run)]) == 0
    # export-model: the model half of `export --checkpoint`, on its own
    assert main(["export-model", "--checkpoint", str(run / "best.pt"), "--out", str(model), "--data", str(data),
                 "--card", str(folder / "card.md")]) == 0
    assert main(["evaluate", "--data", str(data), "--model", f"Mine={model}", "--out", str(out)]) == 0
    assert main(["show", "--data", str(data), "--index", "0", "--out", str(folder / "sample.png")]) == 0
    assert (folder / "sample.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    capsys.readouterr()
    return {"meta": read_metadata(model), "card": (folder / "card.md").read_text(),
            "results": json.loads((out / "results.json").read_text())}


def test_capacitive_pad_end_to_end(arrays, tmp_path, capsys):
    data = tmp_path / "cap.npz"
    assert main(["import", "--readings", str(arrays / "cap_r.npy"), "--images", str(arrays / "cap_i.npy"),
                 "--groups", str(arrays / "cap_g.npy"), "--test-fraction", "0.25", "--reading-unit", "pF",
                 "--image-unit", "fraction", "--data-range", "1", "--out", str(data)]) == 0
    d = load_dataset(data)
    assert d.grid == (41, 72) and d.image_shape == (82, 144) and d.channels.kind == "scalar"
    got = _train_export_evaluate(data, tmp_path, capsys)
    meta, card, results = got["meta"], got["card"], got["results"]
    assert meta["input"]["shape"][1:] == [41, 72, 1] and meta["input"]["units"] == "pF"
    assert len(meta["input"]["offset"]) == 1 and meta["input"]["spread"][0] > 0  # normalised from training data
    assert meta["output"]["image"]["unit"] == "fraction"
    assert "microtesla" not in card and "simulated" not in card and "pF" in card
    assert [r["method"] for r in results["results"]] == ["Bilinear", "Bicubic", "Mine"]
    assert results["psnr_data_range"] == 1.0 and results["image_unit"] == "fraction"
    assert results["baseline_fits"]["Bilinear"]["input_shape"] == [41, 72, 1]
    assert all(np.isfinite(r["psnr_db_mean"]) for r in results["results"])


def test_normalised_taxel_array_end_to_end(arrays, tmp_path, capsys):
    data = tmp_path / "xela.npz"
    assert main(["import", "--arrays", str(arrays / "xela.npz"), "--channel-kind", "scalar",
                 "--reading-unit", "counts", "--image-unit", "grey", "--data-range", "255", "--out", str(data)]) == 0
    got = _train_export_evaluate(data, tmp_path, capsys)
    assert got["meta"]["output"]["image"]["data_range"] == 255.0
    assert got["results"]["psnr_data_range"] == 255.0
    depth = got["results"]["results"][-1]
    assert depth["method"] == "Mine" and np.isfinite(depth["psnr_db_mean"])


@pytest.mark.parametrize("make, problem", [
    (lambda f: (np.zeros((5, 4)), np.zeros((5, 8, 8))), "readings: expected shape (N, rows, cols)"),
    (lambda f: (np.zeros((5, 4, 4)), np.zeros((6, 8, 8))), "images: 6 samples, readings have 5"),
    (lambda f: (np.full((5, 4, 4), np.nan), np.zeros((5, 8, 8))), "readings: 80 NaN or infinite values"),
    (lambda f: (np.zeros((5, 4, 4)), np.full((5, 8, 8), 2.0)), "images: values span [2, 2] mm, outside"),
])
def test_bad_arrays_are_one_line_naming_the_array(make, problem, tmp_path, capsys):
    readings, images = make(tmp_path)
    np.save(tmp_path / "r.npy", readings)
    np.save(tmp_path / "i.npy", images)
    args = ["import", "--readings", str(tmp_path / "r.npy"), "--images", str(tmp_path / "i.npy"),
            "--out", str(tmp_path / "d.npz")]
    if "outside" in problem:
        args += ["--data-range", "1"]
    assert main(args) == 2
    assert_one_line_error(capsys.readouterr().err, "import", problem)
    assert not (tmp_path / "d.npz").exists()


def test_bad_split_group_and_kind_are_one_line(tmp_path, capsys):
    np.save(tmp_path / "r.npy", np.zeros((6, 2, 2)))
    np.save(tmp_path / "i.npy", np.full((6, 4, 4), 0.5))
    np.save(tmp_path / "s.npy", np.array(["val"] * 3 + ["test"] * 3))
    np.save(tmp_path / "s2.npy", np.array(["train"] * 4 + ["val", "test"]))
    np.save(tmp_path / "g.npy", np.array([0, 0, 1, 1, 2, 2]))
    base = ["import", "--readings", str(tmp_path / "r.npy"), "--images", str(tmp_path / "i.npy"),
            "--out", str(tmp_path / "d.npz")]
    cases = [(["--split", str(tmp_path / "s.npy")], "split: no sample is 'train'"),
             (["--split", str(tmp_path / "s2.npy"), "--groups", str(tmp_path / "g.npy")], "groups: group 2"),
             (["--readings", str(tmp_path / "missing.npy")], "missing.npy: no such file")]
    for extra, problem in cases:
        assert main(base + extra) == 2
        assert_one_line_error(capsys.readouterr().err, "import", problem)
    with pytest.raises(SystemExit):  # argparse refuses an unknown channel kind before any work
        main(base + ["--channel-kind", "vector"])
    assert "invalid choice: 'vector'" in capsys.readouterr().err


def test_readings_of_another_sensor_are_not_clamped_to_the_magnetometers_range(arrays, tmp_path, capsys):
    from tactile_manip.perception.reconstruct import OnnxReconstructor

    rng = np.random.default_rng(3)
    readings, images = _blobs(40, (4, 4), (40, 40), rng)
    np.save(tmp_path / "r.npy", 50_000.0 + 10_000.0 * readings)  # raw counts far beyond 10584 (the chip's z range)
    np.save(tmp_path / "i.npy", images)
    data = tmp_path / "counts.npz"
    assert main(["import", "--readings", str(tmp_path / "r.npy"), "--images", str(tmp_path / "i.npy"),
                 "--reading-unit", "counts", "--image-unit", "fraction", "--data-range", "1", "--out", str(data)]) == 0
    got = _train_export_evaluate(data, tmp_path, capsys)
    rec = OnnxReconstructor(tmp_path / "m.onnx")
    assert not rec.magnetic_ut and got["meta"]["input"]["offset"][0] > 40_000
    low, high = np.full((4, 4, 1), 50_000.0), np.full((4, 4, 1), 60_000.0)
    assert not np.array_equal(rec.reconstruct(low).depth_mm, rec.reconstruct(high).depth_mm)
