"""Datasets of labelled presses: targets with units beside or instead of images, format 3 round trips,
format 2 files still read, image consumers refuse a targets-only dataset in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from checks import assert_one_line_error

from tactile_manip.data import (FORMAT_VERSION, PairedDataset, concatenate, from_arrays, load_dataset, read_array,
                                save_dataset, target_from_label, target_unit)
from tactile_manip.errors import DatasetError


def _labelled(n: int = 20, seed: int = 0, **kwargs) -> PairedDataset:
    rng = np.random.default_rng(seed)
    targets = {"x_mm": rng.uniform(-5, 5, n), "y_mm": rng.uniform(-5, 5, n), "force_n": rng.uniform(0, 15, n),
               "in_contact": (rng.uniform(size=n) > 0.3).astype(float)}
    return from_arrays(rng.normal(0, 50, (n, 3, 3, 3)), targets=targets, groups=np.arange(n) // 2,
                       split=np.where(np.arange(n) < 0.8 * n, "train", "test"), **kwargs)


def test_a_targets_only_dataset_names_its_targets_and_units():
    data = _labelled()
    assert not data.has_images and data.has_targets and data.images is None
    assert data.target_names == ("x_mm", "y_mm", "force_n", "in_contact")
    assert data.targets.dtype == np.float32 and data.targets.shape == (20, 4)
    assert data.target_units() == {"x_mm": "mm", "y_mm": "mm", "force_n": "N", "in_contact": "1"}
    np.testing.assert_array_equal(data.target("force_n"), data.targets[:, 2])
    with pytest.raises(DatasetError, match=r"no target 'depth_mm' \(its targets: x_mm, y_mm, force_n, in_contact\)"):
        data.target("depth_mm")
    d = data.describe()
    assert d["image"] is None and d["image_shape"] is None and d["targets"]["force_n"] == "N"
    sub = data.subset(np.array([3, 1]))
    np.testing.assert_array_equal(sub.targets, data.targets[[3, 1]])


def test_images_and_targets_together():
    rng = np.random.default_rng(1)
    data = from_arrays(rng.normal(0, 50, (6, 4, 4, 3)), rng.uniform(0, 1.5, (6, 8, 8)),
                       targets={"depth_mm": rng.uniform(0, 1.5, 6)}, split=["train"] * 4 + ["test"] * 2)
    assert data.has_images and data.has_targets and data.image_shape == (8, 8)
    assert data.target("depth_mm").shape == (6,)


@pytest.mark.parametrize("targets, problem", [
    ({"x": np.zeros(4)}, "target 'x' has no unit suffix"),
    ({"force_n": np.array([1.0, np.nan, 2.0, 3.0])}, "NaN or infinite"),
    ({"force_n": np.zeros(3)}, "3 samples, readings have 4"),
    ({"in_contact": np.array([0, 1, 2, 1])}, "'in_contact' must be 0 or 1"),
])
def test_bad_targets_are_one_error_naming_them(targets, problem):
    with pytest.raises(DatasetError, match=problem):
        from_arrays(np.zeros((4, 3, 3, 3)), targets=targets)


def test_neither_images_nor_targets_is_refused():
    with pytest.raises(DatasetError, match="images or targets"):
        from_arrays(np.zeros((4, 3, 3, 3)))
    with pytest.raises(DatasetError, match="neither"):
        PairedDataset(readings=np.zeros((4, 3, 3, 3), np.float32), images=None, split=np.full(4, "train"))


def test_format_3_round_trip_keeps_targets_groups_and_fingerprint(tmp_path):
    data = _labelled(provenance={"runs": [{"name": "a"}, {"name": "b"}]})
    path = save_dataset(tmp_path / "d", data)
    with np.load(path, allow_pickle=False) as z:
        assert "images" not in z.files and "targets" in z.files
        meta = json.loads(str(z["metadata"]))
    assert meta["format_version"] == FORMAT_VERSION == 3 and meta["image"] is None
    assert meta["target_names"] == list(data.target_names)
    back = load_dataset(path)
    assert back.target_names == data.target_names and not back.has_images
    np.testing.assert_array_equal(back.targets, data.targets)
    np.testing.assert_array_equal(back.groups, data.groups)
    assert back.fingerprint() == data.fingerprint() and back.provenance["runs"][1]["name"] == "b"
    # changing a target changes the fingerprint (it identifies training data)
    moved = from_arrays(data.readings, targets={n: data.target(n) + (n == "force_n") for n in data.target_names},
                        groups=data.groups, split=data.split)
    assert moved.fingerprint() != data.fingerprint()


def _v2_file(path: Path, n: int = 10) -> dict[str, np.ndarray]:
    """The layout format 2 wrote (images always there, no targets), built by hand."""
    rng = np.random.default_rng(2)
    arrays = {"readings": rng.normal(0, 50, (n, 4, 4, 3)).astype(np.float32),
              "images": rng.integers(0, 200, (n, 12, 12), dtype=np.uint8),
              "split": np.array(["train"] * (n - 2) + ["val", "test"]),
              "groups": np.arange(n, dtype=np.int64), "extra__force_n": np.full(n, 3.5, np.float32),
              "metadata": np.array(json.dumps({
                  "format_version": 2, "channels": {"names": ["x", "y", "z"], "kind": "magnetic_vector", "unit": "uT"},
                  "image": {"unit": "mm", "data_range": 2.0, "value_min": 0.0, "pixel_mm": 0.1, "scale": 0.01,
                            "offset": 0.0},
                  "provenance": {"source": "tactile-manip simulate"}}))}
    np.savez_compressed(path, **arrays)
    return arrays


def test_format_2_files_still_load_and_resave_as_format_3(tmp_path):
    arrays = _v2_file(tmp_path / "v2.npz")
    data = load_dataset(tmp_path / "v2.npz")
    assert data.has_images and not data.has_targets and data.target_names == ()
    np.testing.assert_array_equal(data.images, arrays["images"])
    np.testing.assert_allclose(data.depth_mm(), arrays["images"] * np.float32(0.01), rtol=1e-6)
    np.testing.assert_array_equal(data.extra("force_n"), arrays["extra__force_n"])
    assert data.provenance["source"] == "tactile-manip simulate"
    again = load_dataset(save_dataset(tmp_path / "v3.npz", data))
    assert again.fingerprint() == data.fingerprint() and again.image == data.image


def test_image_consumers_refuse_a_targets_only_dataset_in_one_line():
    data = _labelled()
    for call in (data.image_values, data.depth_mm, lambda: data.image_shape):
        with pytest.raises(DatasetError) as e:
            call()
        msg = str(e.value)
        assert "needs images" in msg and "targets only (x_mm, y_mm, force_n, in_contact)" in msg
        assert "\n" not in msg


def test_concatenate_keeps_targets_and_refuses_mixed_kinds():
    a, b = _labelled(seed=0), _labelled(seed=1)
    both = concatenate([a, b])
    assert both.target_names == a.target_names and len(both) == 40
    np.testing.assert_array_equal(both.targets, np.concatenate([a.targets, b.targets]))
    assert len(np.unique(both.groups)) == 20  # each dataset's groups stay apart
    other = from_arrays(a.readings, targets={"x_mm": a.target("x_mm")}, split=a.split)
    with pytest.raises(DatasetError, match=r"dataset 1 has targets \['x_mm'\]"):
        concatenate([a, other])
    rng = np.random.default_rng(3)
    images = from_arrays(a.readings, rng.uniform(0, 1, (20, 4, 4)), split=a.split)
    with pytest.raises(DatasetError, match="dataset 1 has images"):
        concatenate([a, images])


def test_label_units_become_target_units():
    assert target_from_label("force_gf") == ("force_n", pytest.approx(9.80665e-3))
    assert target_from_label("force_kgf") == ("force_n", pytest.approx(9.80665))
    assert target_from_label("x_mm") == ("x_mm", 1.0) and target_from_label("in_contact") == ("in_contact", 1.0)
    assert target_unit("shear_x_n") == "N" and target_unit("in_contact") == "1"
    with pytest.raises(DatasetError, match="label column 'weight' has no unit"):
        target_from_label("weight")


def test_a_file_that_is_not_numpy_is_called_that(tmp_path):
    text = tmp_path / "sensor.csv"
    text.write_text("1.0,2.0,3.0\n")
    with pytest.raises(DatasetError, match="not a numpy file") as e:
        read_array(text)
    assert "Python objects" not in str(e.value)
    with pytest.raises(DatasetError, match="not a numpy file"):
        load_dataset(text)
    np.save(tmp_path / "one.npy", np.zeros(3))
    with pytest.raises(DatasetError, match="holds a single array"):
        load_dataset(tmp_path / "one.npy")


@pytest.mark.parametrize("command", [
    ["show", "--index", "0", "--out", "{tmp}/s.png"],
    ["train", "--config", "configs/train/fast.toml", "--out", "{tmp}/run"],
])
def test_image_commands_refuse_a_targets_only_dataset_in_one_line(command, tmp_path, capsys):
    from tactile_manip.cli import main

    if command[0] == "train":
        pytest.importorskip("torch", reason="train needs torch: pip install torch==2.13.0")
    data = save_dataset(tmp_path / "presses.npz", _labelled())
    args = [a.format(tmp=tmp_path) for a in command] + ["--data", str(data)]
    assert main(args) == 2
    assert_one_line_error(capsys.readouterr().err, command[0], "needs images; this dataset holds targets only")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["presses.npz"]  # nothing written
