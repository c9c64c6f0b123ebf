"""Tiny synthetic paired datasets for fast learning tests (no simulator needed)."""

import numpy as np
import pytest

from tactile_manip.data import PairedDataset, depth_image_spec, quantise_depth, save_dataset


def synthetic_dataset(n_per_object: int = 24, *, grid=(4, 4), image=(32, 32), seed: int = 0) -> PairedDataset:
    """Blobs whose position and size follow the reading: learnable in a few epochs."""
    rng = np.random.default_rng(seed)
    names = ["allen_key", "letter_r", "cylinder_3mm"]
    splits, obj, fields, depths = [], [], [], []
    h, w = image
    yy, xx = np.mgrid[0:h, 0:w]
    for k, name in enumerate(names):
        for i in range(n_per_object):
            cx, cy, r = rng.uniform(0.3, 0.7) * w, rng.uniform(0.3, 0.7) * h, rng.uniform(2, 6)
            depth = np.clip(1.5 - ((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * r * r), 0, None)
            f = np.zeros(grid + (3,), np.float32)
            f[..., 0] = (cx / w - 0.5) * 400
            f[..., 1] = (cy / h - 0.5) * 400
            f[..., 2] = r * 40 + rng.normal(0, 2, grid)
            fields.append(f)
            depths.append(quantise_depth(depth))
            obj.append(k)
            splits.append("test" if k == 2 else ("val" if i >= n_per_object * 3 // 4 else "train"))
    n = len(fields)
    return PairedDataset(
        readings=np.asarray(fields), images=np.asarray(depths), split=np.array(splits), image=depth_image_spec(0.5),
        object_index=np.asarray(obj, np.int16), object_names=np.array(names),
        extras={"pose": np.zeros((n, 5), np.float32), "force_n": np.full(n, 10.0, np.float32)})


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory):
    return save_dataset(tmp_path_factory.mktemp("data") / "tiny.npz", synthetic_dataset())


@pytest.fixture(scope="session")
def other_grid_data(tmp_path_factory):
    """Another sensor: a 5x6 taxel grid and 24x40 images (say a Xela-like pad and a small GelSight crop)."""
    return save_dataset(tmp_path_factory.mktemp("data") / "other.npz",
                        synthetic_dataset(grid=(5, 6), image=(24, 40), seed=1))


@pytest.fixture(scope="session")
def make_synthetic():
    """:func:`synthetic_dataset` itself, for tests that build variants of it."""
    return synthetic_dataset
