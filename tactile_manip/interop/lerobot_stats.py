"""LeRobot's per-feature statistics (``meta/stats.json`` and the episodes' ``stats/...`` columns).

For every feature: ``min``, ``max``, ``mean``, ``std``, ``count`` and the quantiles ``q01 q10 q50 q90 q99``
over its frames, per element of a vector feature; image features per channel over sampled pixels, in
[0, 1] and shaped (3, 1, 1), as lerobot computes them. Values that are NaN (a stream a frame lacks) are left
out; a column without any value gives 0.
"""

from __future__ import annotations

import io
import warnings
from typing import Any

import numpy as np

QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)


def feature_stats(cols: dict[str, Any], features: dict[str, dict]) -> dict[str, dict[str, np.ndarray]]:
    """LeRobot's per-feature statistics (NaN values are left out; images per channel in [0, 1])."""
    out = {}
    for key, ft in features.items():
        if ft["dtype"] == "image":
            values = _image_sample(cols[key])
        else:
            values = np.asarray(cols[key], np.float64).reshape(len(cols[key]), -1)
        out[key] = _stats_of(values, image=ft["dtype"] == "image")
    return out


def _image_sample(pngs: list[bytes | None], most: int = 100, stride: int = 4) -> np.ndarray:
    """(N, 3) pixel values in [0, 1] of up to ``most`` evenly spaced images, every ``stride``-th pixel each way
    (lerobot samples images and shrinks them too)."""
    from PIL import Image

    present = [b for b in pngs if b is not None]
    if not present:
        return np.full((1, 3), np.nan)
    picks = np.unique(np.linspace(0, len(present) - 1, min(most, len(present))).round().astype(int))
    pixels = [np.asarray(Image.open(io.BytesIO(present[i])).convert("RGB"))[::stride, ::stride].reshape(-1, 3) / 255.0
              for i in picks]
    return np.concatenate(pixels)


def _stats_of(values: np.ndarray, *, image: bool) -> dict[str, np.ndarray]:
    """min, max, mean, std, count and quantiles over axis 0; NaN values are left out (an all-NaN column gives 0)."""
    finite = np.isfinite(values)
    v = values if finite.all() else np.where(finite, values, np.nan)
    plain = finite.all()  # the nan-aware functions are several times slower: only where needed
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns
        stats = {"min": (np.min if plain else np.nanmin)(v, axis=0), "max": (np.max if plain else np.nanmax)(v, axis=0),
                 "mean": (np.mean if plain else np.nanmean)(v, axis=0), "std": (np.std if plain else np.nanstd)(v, axis=0)}
        quantiles = (np.quantile if plain else np.nanquantile)(v, QUANTILES, axis=0)
        for q, value in zip(QUANTILES, quantiles):
            stats[f"q{int(round(q * 100)):02d}"] = value
    stats = {k: np.nan_to_num(x, nan=0.0) for k, x in stats.items()}
    stats["count"] = np.array([len(values)])
    if image:  # per channel, shaped (3, 1, 1) as lerobot's image stats
        stats = {k: x if k == "count" else x.reshape(3, 1, 1) for k, x in stats.items()}
    return stats
