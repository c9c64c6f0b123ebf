"""generate_shards: shards are written while the simulation runs, and hold generate()'s samples."""

from pathlib import Path

import numpy as np

from tactile_manip.data import ShardedDataset, load_dataset
from tactile_manip.sim.dataset import DatasetConfig, ObjectSpec, generate, generate_shards


def test_shards_are_written_as_their_presses_finish_and_equal_generate(tmp_path):
    cfg = DatasetConfig(seed=5, images=False, objects=[ObjectSpec("allen_key", 9), ObjectSpec("letter_r", 4,
                                                                                             split="test")])
    written = []  # shard files in the temporary folder each time a press finishes

    def progress(n: int) -> None:
        written.append(len(list(Path(tmp_path).glob(".D.partial-*/shard-*.npz"))))

    path = generate_shards(cfg, tmp_path / "D", shard_size=4, workers=1, progress=progress)
    # after press k, the shards of the first k presses are on disk: one more at every fourth press, the short
    # last one with press 13
    assert written == [k // 4 for k in range(1, 13)] + [4]
    shards = ShardedDataset(path)
    whole = generate(cfg, workers=1)
    assert [e["samples"] for e in shards.entries] == [4, 4, 4, 1]
    assert shards.fingerprint() == whole.fingerprint() == load_dataset(path).fingerprint()
    assert np.array_equal(load_dataset(path).extra("pose"), whole.extra("pose"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D"]
