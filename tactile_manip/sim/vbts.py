"""DTact-style vision-based tactile sensor: the depth image its pipeline reports for a given imprint.

DTact (Lin et al., ICRA 2023) reads depth from the darkening of a semi-transparent gel: a grey-level
difference against a no-contact reference is mapped to depth by a measured lookup table, then smoothed.
We emulate that pipeline on the true imprint ``clip(delta - s, 0)`` (for the thin incompressible layer the
gel surface follows the rigid indenter inside the contact to within ~1 um):

1. depth -> continuous grey difference through the inverse of a measured lookup table (monotone part);
2. camera read noise (Gaussian, in grey levels), rounding to integer levels;
3. the lighting threshold: differences below ``dead_band_levels`` read as 0;
4. grey level -> depth through the table (saturating at the table's last entry);
5. ``blur_passes`` Gaussian passes of ``blur_sigma_mm``.

The two measured tables (9DTact, MIT License, see ``tactile_manip/data/DTACT_LOOKUP_LICENSE.md``) give
about 0.03 mm per level and saturate at 1.92 mm (``sensor_1``) and 1.35 mm (``sensor_2``).
"""

from __future__ import annotations

import functools
from importlib import resources

import numpy as np
from scipy import ndimage

from tactile_manip.checks import check_array
from tactile_manip.sim.params import VbtsParams


@functools.lru_cache(maxsize=4)
def lookup_table(name: str) -> np.ndarray:
    """The measured grey-difference -> depth (mm) table ``name``, index 0 set to 0 and made monotone."""
    if name not in ("sensor_1", "sensor_2"):
        raise ValueError(f"lookup_table must be 'sensor_1' or 'sensor_2', got {name!r}")
    with resources.files("tactile_manip.data").joinpath(f"{name}_pixel_to_depth.npy").open("rb") as f:
        table = np.load(f, allow_pickle=False).astype(np.float64)
    table[0] = 0.0  # index 0 is below the lighting threshold, not a depth
    table = np.maximum.accumulate(table)
    table.setflags(write=False)
    return table


def saturation_depth_mm(name: str) -> float:
    """Largest depth the table ``name`` can report, mm."""
    return float(lookup_table(name)[-1])


def grey_from_depth(depth_mm: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Continuous grey-level difference for a depth (mm), by inverting the monotone table."""
    levels = np.arange(table.size, dtype=np.float64)
    keep = np.concatenate([[True], np.diff(table) > 0])  # strictly increasing knots for np.interp
    return np.interp(depth_mm, table[keep], levels[keep])


def dtact_depth(imprint_mm: np.ndarray, params: VbtsParams, rng: np.random.Generator | None) -> np.ndarray:
    """Depth image (float32 mm, same shape as ``imprint_mm``) as the DTact pipeline would report it.

    ``rng=None`` gives the noise-free pipeline (quantisation, dead band, saturation and blur only).
    """
    imprint = check_array("imprint_mm", imprint_mm)
    if imprint.ndim != 2:
        raise ValueError(f"imprint_mm: expected a 2-D image, got shape {imprint.shape}")
    table = lookup_table(params.lookup_table)
    grey = grey_from_depth(np.clip(imprint, 0.0, None), table)
    if rng is not None and params.noise_grey_levels > 0:
        grey = grey + rng.normal(0.0, params.noise_grey_levels, size=grey.shape)
    level = np.clip(np.rint(grey), 0, table.size - 1).astype(np.intp)
    level[level < params.dead_band_levels] = 0
    depth = table[level]
    sigma_px = params.blur_sigma_mm / params.pixel_mm
    for _ in range(params.blur_passes if sigma_px > 0 else 0):
        depth = ndimage.gaussian_filter(depth, sigma_px, mode="nearest", truncate=3.0)
    return depth.astype(np.float32)
