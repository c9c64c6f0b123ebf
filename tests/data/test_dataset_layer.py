"""The dataset layer: format 2 round trips, format 1 still read (same fingerprint), import from arrays and
every bad input as one DatasetError naming the array."""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from checks import assert_one_line_message

from tactile_manip.data import (ChannelSpec, ImageSpec, PairedDataset, from_arrays, load_dataset, read_array,
                                save_dataset)
from tactile_manip.errors import DatasetError


def _v1_file(path: Path, n: int = 12, rng=None) -> dict[str, np.ndarray]:
    """A file in the layout ``tactile-manip simulate`` wrote before the dataset layer (format 1)."""
    rng = rng or np.random.default_rng(0)
    arrays = {
        "field_ut": rng.normal(0, 100, (n, 4, 4, 3)).astype(np.float32),
        "field_raw_ut": rng.normal(0, 100, (n, 4, 4, 3)).astype(np.float32),
        "saturated": np.zeros((n, 4, 4, 3), bool), "depth_q": rng.integers(0, 200, (n, 20, 20), dtype=np.uint8),
        "object_index": (np.arange(n) % 2).astype(np.int16), "object_names": np.array(["allen_key", "rod"]),
        "split": np.array(["train"] * (n - 4) + ["val", "val", "test", "test"]),
        "pose": rng.normal(0, 1, (n, 5)).astype(np.float32), "force_n": np.full(n, 10.5, np.float32),
        "approach_mm": np.ones(n, np.float32), "skin_approach_mm": np.ones(n, np.float32),
        "contact": np.ones(n, bool),
        "metadata": np.array(json.dumps({"format_version": 1, "depth_scale_mm": 0.01, "pixel_mm": 0.25,
                                         "field_axes": ["x", "y", "z"], "field_unit": "uT", "config": {"seed": 3}}))}
    np.savez_compressed(path, **arrays)
    return arrays


def test_format_1_reads_with_its_old_fingerprint_and_fields(tmp_path):
    arrays = _v1_file(tmp_path / "v1.npz")
    data = load_dataset(tmp_path / "v1.npz")
    h = hashlib.sha256()  # how format-1 code fingerprinted a file
    for a in (arrays["field_ut"], arrays["depth_q"], arrays["split"].astype("U5"), arrays["object_index"]):
        h.update(np.ascontiguousarray(a).tobytes())
    assert data.fingerprint() == h.hexdigest()[:16]
    np.testing.assert_array_equal(data.field_ut, arrays["field_ut"])
    np.testing.assert_allclose(data.depth_mm(), arrays["depth_q"] * np.float32(0.01), rtol=1e-6)
    assert data.image == ImageSpec(unit="mm", data_range=2.0, pixel_mm=0.25, scale=0.01)
    assert data.channels == ChannelSpec()
    np.testing.assert_array_equal(data.extra("pose"), arrays["pose"])
    assert data.provenance["config"] == {"seed": 3} and data.provenance["read_from_format"] == 1
    # re-saved as format 2 it is the same data
    again = load_dataset(save_dataset(tmp_path / "v2.npz", data))
    assert again.fingerprint() == data.fingerprint() and again.image == data.image
    assert sorted(again.extras) == sorted(data.extras)


def test_format_2_round_trip_of_an_imported_scalar_dataset(tmp_path):
    rng = np.random.default_rng(1)
    data = from_arrays(rng.normal(0, 1, (30, 5, 7)), rng.uniform(0, 1, (30, 10, 14)), groups=np.repeat(np.arange(10), 3),
                       image_unit="fraction", data_range=1.0, reading_unit="pF", pixel_mm=0.5)
    back = load_dataset(save_dataset(tmp_path / "d", data))
    assert back.grid == (5, 7) and back.image_shape == (10, 14) and back.readings.shape == (30, 5, 7, 1)
    assert back.channels == ChannelSpec(names=("c0",), kind="scalar", unit="pF")
    assert back.image.unit == "fraction" and back.image.data_range == 1.0 and back.image.pixel_mm == 0.5
    np.testing.assert_array_equal(back.groups, data.groups)
    assert back.fingerprint() == data.fingerprint()
    assert back.objects(np.arange(3)).tolist() == ["all"] * 3
    with pytest.raises(DatasetError, match="not a magnetic field in uT"):
        back.field_ut
    with pytest.raises(DatasetError, match="not depth in mm"):
        back.depth_mm()
    with pytest.raises(DatasetError, match="no 'pose' per sample"):
        back.extra("pose")


def test_defaults_follow_the_channel_count():
    rng = np.random.default_rng(2)
    mag = from_arrays(rng.normal(0, 50, (20, 4, 4, 3)), rng.uniform(0, 1.5, (20, 8, 8)))
    assert mag.channels == ChannelSpec() and mag.image.value_min == 0.0
    assert mag.image.data_range == pytest.approx(float(mag.images.max()))
    two = from_arrays(rng.normal(0, 1, (20, 3, 3, 2)), rng.uniform(0, 1, (20, 8, 8)))
    assert two.channels.kind == "scalar" and two.channels.names == ("c0", "c1") and two.channels.unit == "1"


def test_groups_are_never_cut_and_the_split_is_seeded():
    rng = np.random.default_rng(3)
    groups = rng.integers(0, 40, 400)
    kw = dict(groups=groups, val_fraction=0.2, test_fraction=0.2, seed=5, data_range=1.0)
    a = from_arrays(rng.normal(0, 1, (400, 2, 2)), rng.uniform(0, 1, (400, 4, 4)), **kw)
    for g in np.unique(groups):
        assert len(np.unique(a.split[groups == g])) == 1
    shares = [np.mean(a.split == s) for s in ("train", "val", "test")]
    assert shares[0] > 0.45 and 0.1 < shares[1] < 0.3 and 0.1 < shares[2] < 0.3
    b = from_arrays(a.readings, a.image_values(), **kw)
    np.testing.assert_array_equal(a.split, b.split)


@pytest.mark.parametrize("kwargs, array, problem", [
    (dict(readings=np.zeros((4, 4))), "readings", "rank 2"),
    (dict(images=np.zeros((5, 8, 8))), "images", "5 samples, readings have 6"),
    (dict(images=np.zeros((6, 8))), "images", "rank 2"),
    (dict(readings=np.full((6, 2, 2), np.nan)), "readings", "NaN"),
    (dict(images=np.full((6, 8, 8), 3.0), data_range=1.0), "images", "outside their stated range"),
    (dict(split=np.array(["val"] * 3 + ["test"] * 3)), "split", "nothing to train"),
    (dict(split=np.array(["train"] * 5 + ["holdout"])), "split", "'holdout'"),
    (dict(split=np.array(["train"] * 4 + ["val", "test"]), groups=np.array([0, 0, 1, 1, 2, 2])), "groups",
     "group 2 is in several splits"),
    (dict(channel_kind="vector"), "channel kind", "'vector'"),
    (dict(val_fraction=0.5, test_fraction=0.5), "val_fraction + test_fraction", "leaves nothing to train"),
    (dict(groups=np.array([0, 0, 0, 1, 1, 1])), "groups", "2 groups leave none for training"),
    (dict(channel_names=("a", "b")), "channel names", "2 names"),
])
def test_bad_inputs_name_the_array(kwargs, array, problem):
    args = dict(readings=np.ones((6, 2, 2)), images=np.full((6, 8, 8), 0.5))
    args.update(kwargs)
    with pytest.raises(DatasetError) as info:
        from_arrays(args.pop("readings"), args.pop("images"), **args)
    msg = assert_one_line_message(str(info.value), problem)
    assert msg.startswith(array), msg


def test_read_array_sources(tmp_path):
    a = np.arange(12.0).reshape(3, 4)
    np.save(tmp_path / "a.npy", a)
    np.savez(tmp_path / "b.npz", x=a)
    np.testing.assert_array_equal(read_array(tmp_path / "a.npy"), a)
    np.testing.assert_array_equal(read_array(tmp_path / "b.npz", "x"), a)
    with pytest.raises(DatasetError, match=r"no array 'y'; it holds \['x'\]"):
        read_array(tmp_path / "b.npz", "y")
    np.save(tmp_path / "o.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(DatasetError, match="Python objects"):
        read_array(tmp_path / "o.npy")
    with pytest.raises(DatasetError, match="is a directory"):
        read_array(tmp_path)
    h5py = pytest.importorskip("h5py", reason="HDF5 import needs the hdf5 extra (h5py)")
    with h5py.File(tmp_path / "c.h5", "w") as f:
        f["readings"] = a
    np.testing.assert_array_equal(read_array(tmp_path / "c.h5", "readings"), a)
    with pytest.raises(DatasetError, match="no dataset 'images'"):
        read_array(tmp_path / "c.h5", "images")


def test_a_dataset_checks_its_own_shapes():
    with pytest.raises(DatasetError, match=r"readings: expected shape \(N, rows, cols, 3\)"):
        PairedDataset(readings=np.zeros((2, 4, 4, 2), np.float32), images=np.zeros((2, 4, 4)),
                      split=np.array(["train", "val"]))
    with pytest.raises(ValueError, match="channel kind"):
        ChannelSpec(kind="tensor")
    with pytest.raises(ValueError, match="data_range must be > 0"):
        ImageSpec(data_range=0.0)


def test_import_from_hdf5_without_h5py_is_one_line_naming_the_extra(tmp_path, monkeypatch, capsys):
    from tactile_manip.cli import main

    monkeypatch.setitem(sys.modules, "h5py", None)  # import h5py raises ImportError, as when not installed
    (tmp_path / "mine.h5").write_bytes(b"")
    assert main(["import", "--arrays", str(tmp_path / "mine.h5"), "--out", str(tmp_path / "d.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [err] and err.startswith("tactile-manip import: error: reading HDF5 needs h5py"), err
    assert 'pip install -e ".[hdf5]"' in err and not (tmp_path / "d.npz").exists()
