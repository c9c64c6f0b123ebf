"""The block store of distributed runs: lossless round trips without pickle, and refusals (no Ray needed)."""

import numpy as np
import pytest

from tactile_manip.cluster.blocks import BlockStore, blocks_folder, remove_blocks, run_key
from tactile_manip.cluster.simulate import block_bounds
from tactile_manip.errors import ClusterError


def _results(n, rng):
    return [{"field_ut": rng.normal(size=(4, 4, 3)).astype(np.float32), "depth_q": rng.integers(0, 255, (5, 5), dtype=np.uint8),
             "pose": [float(v) for v in rng.normal(size=5)], "force_n": float(rng.uniform(2, 15)),
             "contact": bool(i % 2), "no_image": None, "sensor_params": {"gap_mm": float(rng.uniform()), "e_kpa": float(rng.uniform())}}
            for i in range(n)]


def test_block_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    store = BlockStore(tmp_path / "d.npz", run_key({"a": 1}, 4))
    assert store.open() == {}
    results = _results(4, rng)
    store.save(8, 12, results)
    assert store.open() == {8: 12}
    back = store.load(8, 12)
    for a, b in zip(results, back):
        assert list(a) == list(b)
        np.testing.assert_array_equal(a["field_ut"], b["field_ut"])
        assert b["field_ut"].dtype == np.float32 and b["depth_q"].dtype == np.uint8
        assert np.asarray(a["pose"]).tolist() == np.asarray(b["pose"]).tolist()
        assert b["no_image"] is None
        assert a["force_n"] == b["force_n"] and bool(a["contact"]) == bool(b["contact"])
        assert a["sensor_params"] == b["sensor_params"] and list(a["sensor_params"]) == list(b["sensor_params"])


def test_blocks_of_another_run_are_refused(tmp_path):
    out = tmp_path / "d.npz"
    BlockStore(out, run_key({"a": 1}, 4)).save(0, 2, _results(2, np.random.default_rng(0)))
    with pytest.raises(ClusterError, match="another config or block size"):
        BlockStore(out, run_key({"a": 2}, 4)).open()
    with pytest.raises(ClusterError, match="another config or block size"):
        BlockStore(out, run_key({"a": 1}, 8)).open()
    remove_blocks(out)
    assert not blocks_folder(out).exists()


def test_a_damaged_block_is_named(tmp_path):
    out = tmp_path / "d.npz"
    store = BlockStore(out, run_key({}, 2))
    store.save(0, 2, _results(2, np.random.default_rng(0)))
    store.path(0, 2).write_bytes(b"not a numpy file")
    with pytest.raises(ClusterError, match="delete it"):
        store.load(0, 2)


def test_block_bounds_cover_every_sample_once():
    bounds = block_bounds(70, 32)
    assert bounds == [(0, 32), (32, 64), (64, 70)]
    assert block_bounds(0, 8) == []
    with pytest.raises(ValueError, match="--block-size must be >= 1"):
        block_bounds(10, 0)
