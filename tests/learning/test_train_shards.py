"""Training on shard folders: a few shards in memory at a time, every training sample once per epoch, the same
data description and fingerprint as the one-file form."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch", reason="training tests need torch: pip install torch==2.13.0")
import torch

from tactile_manip.data import ChannelSpec, load_dataset, save_sharded
from tactile_manip.learning.cvae.data import (InputSpec, StreamedData, StreamedPairs, TensorPairs, open_training_data,
                                              select)
from tactile_manip.learning.cvae.train import TrainConfig, evaluate_split, train
from tactile_manip.learning.cvae.model import SuperMagCVAE, preset


ROOT = Path(__file__).resolve().parents[2]
TINY = dict(preset="small", batch_size=8, lr=3e-3, epochs=2, patience=50, threads=1, seed=0)


def _numbered(make_synthetic, n_per_object: int = 24):
    """The synthetic dataset with each sample's index in its first reading value (to follow samples around)."""
    data = make_synthetic(n_per_object)
    data.readings[:, 0, 0, 0] = np.arange(len(data))
    return data


@pytest.fixture
def sharded(tmp_path, make_synthetic):
    data = _numbered(make_synthetic)
    return data, save_sharded(tmp_path / "D", data, shard_size=10)


def test_streamed_epoch_holds_at_most_two_shards_and_sees_every_training_sample_once(sharded):
    data, path = sharded
    pairs = StreamedPairs(StreamedData([load_shards(path)]), "train", buffer_parts=2)
    gen = torch.Generator().manual_seed(0)
    seen = [f[:, 0, 0, 0].long() for f, _ in pairs.batches(8, gen)]
    seen = torch.cat(seen).tolist()
    train_index = data.indices("train")
    assert len(seen) == len(train_index) // 8 * 8 == pairs.batch_count(8) * 8
    assert len(set(seen)) == len(seen) and set(seen) <= set(train_index.tolist())
    shards_with_train = sum(1 for e in load_shards(path).entries if e["splits"]["train"])
    assert pairs.loads == shards_with_train  # each shard read once per epoch
    largest = max(e["splits"]["train"] for e in load_shards(path).entries)
    assert 0 < pairs.peak_samples <= 2 * largest  # never more than two shards' samples held
    assert pairs.held == 0
    assert seen != sorted(seen)  # shuffled, not in file order
    one_shard = StreamedPairs(StreamedData([load_shards(path)]), "train", buffer_parts=1)
    list(one_shard.batches(8, torch.Generator().manual_seed(0)))
    assert one_shard.peak_samples <= largest + 7  # one shard, and less than a batch carried over


def test_ranks_share_each_global_batch(sharded):
    _, path = sharded
    pairs = StreamedPairs(StreamedData([load_shards(path)]), "train")
    whole = [f[:, 0, 0, 0] for f, _ in pairs.batches(8, torch.Generator().manual_seed(3))]
    halves = [[f[:, 0, 0, 0] for f, _ in pairs.batches(8, torch.Generator().manual_seed(3), rank=r, world=2)]
              for r in (0, 1)]
    assert all(torch.equal(w, torch.cat([a, b])) for w, a, b in zip(whole, *halves))


def test_validation_chunks_and_images_match_the_in_memory_split(sharded):
    data, path = sharded
    pairs = StreamedPairs(StreamedData([load_shards(path)]), "val", objects=("allen_key",))
    memory = TensorPairs(data, select(data, "val", ("allen_key",)))
    fields, images = zip(*pairs.chunks(5))
    assert torch.equal(torch.cat(fields), memory.field)
    assert torch.equal(torch.cat(images), memory.images(slice(None)))
    model = SuperMagCVAE(preset("small", taxel_rows=4, taxel_cols=4, image_h=32, image_w=32))
    spec = InputSpec()
    streamed, held = evaluate_split(model, pairs, spec), evaluate_split(model, memory, spec)
    assert streamed["mse"] == pytest.approx(held["mse"], rel=1e-5)
    assert streamed["psnr"] == pytest.approx(held["psnr"], rel=1e-5)


def test_streamed_normalisation_matches_the_in_memory_one(tmp_path, make_synthetic):
    data = dataclasses.replace(make_synthetic(), channels=ChannelSpec(kind="scalar", names=("p", "q", "r"),
                                                                         unit="kPa"))
    path = save_sharded(tmp_path / "D", data, shard_size=7)
    streamed = InputSpec.for_stream(StreamedPairs(StreamedData([load_shards(path)]), "train"), clamp_ut=500,
                                    axes="xyz", clamp_std=5)
    held = InputSpec.for_data(data, data.indices("train"), clamp_ut=500, axes="xyz", clamp_std=5)
    np.testing.assert_allclose(streamed.offset, held.offset, rtol=1e-9)
    np.testing.assert_allclose(streamed.spread, held.spread, rtol=1e-9)


def test_train_on_a_shard_folder_records_the_one_file_fingerprint_and_resumes(sharded, tmp_path):
    data, path = sharded
    summary = train(TrainConfig(**TINY), path, tmp_path / "run")
    assert summary["epochs_run"] == 2 and np.isfinite(summary["history"][-1]["loss"])
    assert summary["data_fingerprint"] == data.fingerprint() == load_dataset(path).fingerprint()
    assert summary["history"][-1]["epoch_fraction"] == 1.0
    ckpt = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)
    assert ckpt["data"]["samples"] == len(data) and ckpt["data"]["shards"] == 8
    assert ckpt["data"]["splits"] == {s: len(data.indices(s)) for s in ("train", "val", "test")}
    again = train(TrainConfig(**{**TINY, "epochs": 3}), path, tmp_path / "run", resume=True)
    assert [r["epoch"] for r in again["history"]] == [1, 2, 3]


def test_several_datasets_one_of_them_sharded_train_together(sharded, tiny_data, tmp_path):
    data, path = sharded
    view = open_training_data([path, tiny_data])
    assert isinstance(view, StreamedData) and len(view) == len(data) + len(load_dataset(tiny_data))
    pairs = StreamedPairs(view, "train", objects=("letter_r",), drop_bottomed_out=True)
    assert len(pairs) == 2 * len(data.indices("train", ("letter_r",)))
    summary = train(TrainConfig(**{**TINY, "epochs": 1, "objects": ["letter_r"]}), [path, tiny_data],
                    tmp_path / "run")
    assert summary["epochs_run"] == 1
    assert json.loads((tmp_path / "run" / "history.json").read_text())["data_fingerprint"] == view.fingerprint()
    with pytest.raises(ValueError, match="objects \\['nope'\\] are not in the dataset"):
        StreamedPairs(view, "train", objects=("nope",))


def test_files_only_still_load_into_memory(tiny_data):
    data = open_training_data([tiny_data])
    assert not isinstance(data, StreamedData) and data.fingerprint() == load_dataset(tiny_data).fingerprint()


def load_shards(path):
    from tactile_manip.data import ShardedDataset

    return ShardedDataset(path)


def test_shard_buffer_is_validated_and_used(sharded, tmp_path, monkeypatch):
    with pytest.raises(ValueError, match=r"shard_buffer must be an integer in \[1, 64\], got 0"):
        TrainConfig(shard_buffer=0)
    _, path = sharded
    made = []
    real = StreamedPairs.__init__

    def spy(self, *args, **kwargs):
        real(self, *args, **kwargs)
        made.append(self)

    monkeypatch.setattr(StreamedPairs, "__init__", spy)
    train(TrainConfig(**{**TINY, "epochs": 1, "shard_buffer": 3}), path, tmp_path / "run")
    assert made[0].split == "train" and made[0].buffer_parts == 3
    assert made[0].peak_samples <= 3 * max(made[0].counts)


def test_train_refuses_a_shard_folder_with_a_missing_shard_in_one_line(sharded, tmp_path):
    import subprocess
    import sys

    _, path = sharded
    (path / "shard-00004.npz").unlink()
    config = ROOT / "configs" / "train" / "fast.toml"
    done = subprocess.run([sys.executable, "-m", "tactile_manip", "train", "--config", str(config), "--data",
                           str(path), "--out", str(tmp_path / "run")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and done.stderr.strip().count("\n") == 0
    assert "shard-00004.npz named in manifest.json is missing" in done.stderr
    assert not (tmp_path / "run" / "checkpoint.pt").exists()
