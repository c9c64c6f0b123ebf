"""Several datasets trained on as one: concatenate keeps splits, merges object names, keeps groups apart, keeps
common extras; mismatched specs are one DatasetError naming the difference; select drops bottomed-out presses."""

from __future__ import annotations

import numpy as np
import pytest
from checks import TORCH_MISSING

from tactile_manip.data import ChannelSpec, PairedDataset, concatenate, load_datasets, save_dataset
from tactile_manip.errors import DatasetError


def _data(n: int, names: list[str], *, groups: bool = False, extra: dict | None = None, seed: int = 0,
          channels: ChannelSpec | None = None) -> PairedDataset:
    rng = np.random.default_rng(seed)
    split = np.array((["train", "val", "test"] * n)[:n])
    return PairedDataset(readings=rng.normal(0, 50, (n, 4, 4, 3)).astype(np.float32),
                         images=rng.integers(0, 200, (n, 8, 8), dtype=np.uint8), split=split,
                         channels=channels or ChannelSpec(),
                         object_index=(np.arange(n) % len(names)).astype(np.int16), object_names=np.array(names),
                         groups=np.arange(n) // 2 + 100 if groups else None, extras=extra or {},
                         provenance={"source": f"seed {seed}"})


def test_samples_splits_objects_and_extras_in_order():
    a = _data(6, ["allen_key", "rod"], extra={"force_n": np.full(6, 10.5), "pose": np.zeros((6, 5))})
    b = _data(4, ["rod", "ridge"], seed=1, extra={"force_n": np.full(4, 3.0), "bottomed_out": np.ones(4, bool)})
    both = concatenate([a, b])
    assert len(both) == 10
    np.testing.assert_array_equal(both.readings, np.concatenate([a.readings, b.readings]))
    np.testing.assert_array_equal(both.split, np.concatenate([a.split, b.split]))
    assert both.objects().tolist() == a.objects().tolist() + b.objects().tolist()
    assert both.object_names.tolist() == ["allen_key", "rod", "ridge"]  # "rod" once
    np.testing.assert_array_equal(both.extra("force_n"), [10.5] * 6 + [3.0] * 4)
    assert sorted(both.extras) == ["force_n"]
    assert both.provenance["dropped_extras"] == ["bottomed_out", "pose"]
    assert [p["fingerprint"] for p in both.provenance["parts"]] == [a.fingerprint(), b.fingerprint()]


def test_groups_never_span_two_datasets():
    a, b = _data(6, ["x"], groups=True), _data(4, ["x"], seed=1, groups=True)
    both = concatenate([a, _data(3, ["x"], seed=2), b])  # the middle one has no groups: one per sample
    g = both.groups
    assert set(g[:6]).isdisjoint(g[6:9]) and set(g[6:9]).isdisjoint(g[9:]) and set(g[:6]).isdisjoint(g[9:])
    assert len(set(g[6:9])) == 3 and len(set(g[:6])) == 3


def test_mismatched_channels_or_geometry_is_one_error_naming_it():
    a = _data(3, ["x"])
    with pytest.raises(DatasetError, match="channels"):
        concatenate([a, _data(3, ["x"], channels=ChannelSpec(names=("bx", "by", "bz"), unit="mT"))])
    small = PairedDataset(readings=a.readings, images=a.images[:, :4, :4], split=a.split)
    with pytest.raises(DatasetError, match=r"\(4, 4\) images"):
        concatenate([a, small])
    with pytest.raises(DatasetError, match="at least one"):
        concatenate([])


def test_load_datasets_reads_one_or_several_files(tmp_path):
    a, b = _data(6, ["x"]), _data(3, ["y"], seed=1)
    pa, pb = save_dataset(tmp_path / "a.npz", a), save_dataset(tmp_path / "b.npz", b)
    assert load_datasets([pa]).fingerprint() == a.fingerprint()
    both = load_datasets([pa, pb])
    assert both.fingerprint() == concatenate([a, b]).fingerprint()
    assert [p["path"] for p in both.provenance["parts"]] == [str(pa), str(pb)]
    with pytest.raises(DatasetError, match="more than once"):
        load_datasets([pa, tmp_path / "." / "a.npz"])
    with pytest.raises(DatasetError, match="no dataset file"):
        load_datasets([])


def test_labelled_presses_with_and_without_images_join_when_images_are_left_unread(tmp_path):
    import dataclasses

    targets = {"targets": np.arange(12, dtype=np.float32).reshape(6, 2), "target_names": ("x_mm", "force_n")}
    pictured = dataclasses.replace(_data(6, ["x"]), **targets)
    bare = dataclasses.replace(_data(6, ["y"], seed=1), images=None, **targets)
    pa, pb = save_dataset(tmp_path / "a.npz", pictured), save_dataset(tmp_path / "b.npz", bare)
    with pytest.raises(DatasetError, match="images"):
        load_datasets([pa, pb])
    both = load_datasets([pa, pb], images=False)
    assert not both.has_images and len(both) == 12
    np.testing.assert_array_equal(both.targets, np.concatenate([pictured.targets, bare.targets]))
    # images without targets are all such a dataset holds: they stay
    assert load_datasets([save_dataset(tmp_path / "c.npz", _data(3, ["z"]))], images=False).has_images


def test_select_drops_flagged_presses_and_keeps_data_without_the_flag():
    torch = pytest.importorskip("torch", reason=TORCH_MISSING)  # noqa: F841 (learning.cvae.data imports torch)
    from tactile_manip.learning.cvae.data import select

    flagged = np.zeros(9, bool)
    flagged[[0, 3]] = True  # both in "train"
    data = _data(9, ["x"], extra={"bottomed_out": flagged})
    assert select(data, "train").tolist() == [0, 3, 6]
    assert select(data, "train", drop_bottomed_out=True).tolist() == [6]
    plain = _data(9, ["x"])
    assert select(plain, "train", drop_bottomed_out=True).tolist() == [0, 3, 6]
    flagged[6] = True
    with pytest.raises(ValueError, match="all 3 presses of split 'train' are flagged bottomed_out"):
        select(_data(9, ["x"], extra={"bottomed_out": flagged}), "train", drop_bottomed_out=True)
