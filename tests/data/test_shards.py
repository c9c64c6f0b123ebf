"""Sharded datasets: the folder form holds the same samples and fingerprint as one file, is written atomically,
and refuses missing, unlisted or altered shards in one line."""

import json
import subprocess
import sys

import numpy as np
import pytest

from tactile_manip.data import (PairedDataset, ShardedDataset, ShardWriter, check_dataset_file, depth_image_spec,
                                iter_shards, load_dataset, save_dataset, save_sharded)
from tactile_manip.data.shards import streamed_fingerprint
from tactile_manip.errors import DatasetError

ARRAYS = ("readings", "images", "split", "object_index", "groups", "targets")


def _dataset(n: int = 23, *, seed: int = 0, with_images: bool = True) -> PairedDataset:
    rng = np.random.default_rng(seed)
    return PairedDataset(
        readings=rng.normal(0, 100, (n, 4, 4, 3)).astype(np.float32),
        images=rng.integers(0, 255, (n, 8, 8), dtype=np.uint8) if with_images else None,
        split=rng.choice(["train", "val", "test"], n), image=depth_image_spec(0.1),
        object_index=rng.integers(0, 3, n).astype(np.int16), object_names=np.array(["a", "bb", "ccc"]),
        groups=rng.integers(0, 5, n).astype(np.int64), targets=rng.normal(size=(n, 2)).astype(np.float32),
        target_names=("x_mm", "force_n"), extras={"pose": rng.normal(size=(n, 5)).astype(np.float32)},
        provenance={"source": "test"})


@pytest.mark.parametrize("shard_size", [1, 5, 23, 100])
@pytest.mark.parametrize("with_images", [True, False])
def test_sharded_round_trip_equals_the_single_file(tmp_path, shard_size, with_images):
    data = _dataset(with_images=with_images)
    path = save_sharded(tmp_path / "D", data, shard_size=shard_size)
    one = load_dataset(save_dataset(tmp_path / "one.npz", data))
    back = load_dataset(path)
    sharded = ShardedDataset(path)
    assert sharded.shard_count == -(-len(data) // shard_size) and len(sharded) == len(data)
    assert sharded.fingerprint() == back.fingerprint() == one.fingerprint() == data.fingerprint()
    for name in ARRAYS:
        a, b = getattr(one, name), getattr(back, name)
        assert (a is None and b is None) or np.array_equal(a, b), name
    assert np.array_equal(back.extra("pose"), data.extra("pose"))
    assert back.objects().tolist() == data.objects().tolist()
    assert sharded.splits == {s: int(np.sum(data.split == s)) for s in ("train", "val", "test")}
    assert [len(d) for d in iter_shards(path)] == [e["samples"] for e in sharded.entries]


def test_the_streamed_fingerprint_hashes_the_same_bytes_as_the_dataset(tmp_path):
    data = _dataset(40, seed=3)
    files = [save_dataset(tmp_path / f"s{i}.npz", data.subset(np.arange(i, min(i + 7, 40))))
             for i in range(0, 40, 7)]
    assert streamed_fingerprint(files) == data.fingerprint()
    assert streamed_fingerprint(files[::-1]) != data.fingerprint()  # the order of the samples counts


def test_a_missing_shard_an_unlisted_shard_and_an_altered_shard_are_refused(tmp_path):
    data = _dataset()
    path = save_sharded(tmp_path / "D", data, shard_size=5)
    (path / "shard-00002.npz").rename(tmp_path / "kept.npz")
    with pytest.raises(DatasetError, match="shard shard-00002.npz named in manifest.json is missing"):
        load_dataset(path)
    (tmp_path / "kept.npz").rename(path / "shard-00002.npz")
    save_dataset(path / "shard-00009.npz", data.subset(np.arange(3)))
    with pytest.raises(DatasetError, match="shard shard-00009.npz is not in manifest.json"):
        check_dataset_file(path)
    (path / "shard-00009.npz").unlink()
    save_dataset(path / "shard-00001.npz", _dataset(seed=1).subset(np.arange(5)))  # same size, other samples
    with pytest.raises(DatasetError, match="shard shard-00001.npz has fingerprint"):
        load_dataset(path)
    ShardedDataset(path).load_shard(0)  # the others still read


def test_a_failed_write_leaves_nothing_under_the_final_name(tmp_path):
    data = _dataset()
    with pytest.raises(RuntimeError, match="interrupted"):
        with ShardWriter(tmp_path / "D", shard_size=5) as writer:
            writer.write(data.subset(np.arange(5)))
            assert not (tmp_path / "D").exists()  # shards go to a temporary folder first
            raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []
    save_sharded(tmp_path / "D", data, shard_size=5)
    with pytest.raises(DatasetError, match="exists"):
        save_sharded(tmp_path / "D", data, shard_size=5)
    other = _dataset(seed=2)
    assert ShardedDataset(save_sharded(tmp_path / "D", other, shard_size=4, force=True)).fingerprint() == \
        other.fingerprint()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D"]


def test_a_bad_manifest_is_one_clear_error(tmp_path):
    path = save_sharded(tmp_path / "D", _dataset(), shard_size=5)
    manifest = json.loads((path / "manifest.json").read_text())
    manifest["samples"] += 1
    (path / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match="says 24 samples, its shards hold 23"):
        load_dataset(path)
    (path / "manifest.json").write_text("{")
    with pytest.raises(DatasetError, match="cannot read manifest.json"):
        load_dataset(path)
    with pytest.raises(DatasetError, match="without manifest.json"):
        check_dataset_file(tmp_path)


def test_simulate_shard_size_equals_the_one_file_run_and_readers_take_the_folder(tmp_path):
    config = tmp_path / "tiny.toml"
    config.write_text('seed = 3\nimages = true\n[[objects]]\nname = "allen_key"\ncount = 7\n'
                      '[[objects]]\nname = "cylinder"\ncount = 4\nsplit = "test"\n')
    def simulate(*extra):
        return subprocess.run([sys.executable, "-m", "tactile_manip", "simulate", "--config", str(config),
                               "--workers", "1", *extra], capture_output=True, text=True, timeout=300)

    one = simulate("--out", str(tmp_path / "one.npz"))
    assert one.returncode == 0, one.stderr
    sharded = simulate("--out", str(tmp_path / "D"), "--shard-size", "3")
    assert sharded.returncode == 0, sharded.stderr
    assert "4 shards" in sharded.stdout
    a, b = load_dataset(tmp_path / "one.npz"), load_dataset(tmp_path / "D")
    assert a.fingerprint() == b.fingerprint() == ShardedDataset(tmp_path / "D").fingerprint()
    for name in a.extras:
        assert np.array_equal(a.extra(name), b.extra(name)), name
    again = simulate("--out", str(tmp_path / "D"), "--shard-size", "3")
    assert again.returncode == 2 and "exists" in again.stderr and len(again.stderr.strip().splitlines()) == 1
    (tmp_path / "D" / "shard-00003.npz").unlink()
    show = subprocess.run([sys.executable, "-m", "tactile_manip", "show", "--data", str(tmp_path / "D"),
                           "--out", str(tmp_path / "s.png")], capture_output=True, text=True, timeout=120)
    assert show.returncode == 2 and show.stderr.strip().count("\n") == 0
    assert "shard-00003.npz" in show.stderr


def test_shards_that_mean_different_things_are_refused(tmp_path):
    data = _dataset()
    other_names = PairedDataset(readings=data.readings[:3], images=data.images[:3], split=data.split[:3],
                                image=data.image, object_index=data.object_index[:3],
                                object_names=np.array(["x", "y", "z"]), groups=data.groups[:3],
                                targets=data.targets[:3], target_names=data.target_names,
                                extras={"pose": data.extra("pose")[:3]})
    with pytest.raises(DatasetError, match="shard 1 differs from shard 0"):
        with ShardWriter(tmp_path / "D", shard_size=5) as writer:
            writer.write(data.subset(np.arange(5)))
            writer.write(other_names)
    assert not (tmp_path / "D").exists()
