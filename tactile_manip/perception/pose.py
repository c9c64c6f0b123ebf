"""From a depth image to the in-plane angle of the contact: outlier removal, Gaussian filter, PCA.

Pure functions over (H, W) depth images in mm (pixel (0, 0) at the pad's (-x, +y) corner). The angle is
the principal axis of the depth-weighted second moments of the contact, counter-clockwise from +x and
wrapped to (-pi/2, pi/2]; its confidence is ``1 - lambda_minor / lambda_major``. Empty, tiny or isotropic
contacts give ``defined=False`` with a reason, never NaN.

:func:`angle_from_image` computes what the full-image float64 pipeline
(:func:`~tactile_manip.evaluation.pose_reference.reference_angle_from_image`) computes, at a fraction of its
cost: in the image's own precision (float32 for reconstructions), and only over the contact's bounding box
plus twice the Gaussian's reach (nothing outside can change the result: a pixel below the threshold
everywhere within the filter radius filters to below the threshold), with the filter as small banded matrix
products and the moments from a column sum and one matrix-vector product. On float32 images (reconstructions)
all of that after the background runs in one call into C when the optional kernel is built
(:mod:`~tactile_manip.perception.pose_kernel`, about a third of the numpy path's time), with the same results
to float32 rounding; tests/perception/test_pose_fast.py holds both paths to the float64 reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import ndimage

from tactile_manip.checks import check_finite_scalar
from tactile_manip.perception import pose_kernel
from tactile_manip.types import AngleEstimate

DEFAULT_THRESHOLD_MM = 0.1     # pixels shallower than this are not contact
DEFAULT_SIGMA_MM = 0.3         # Gaussian filter before PCA
MIN_CONTACT_PX = 20            # fewer contact pixels: angle undefined
ISOTROPY_LIMIT = 0.9           # minor/major eigenvalue ratio above this: angle undefined
ISOTROPIC_REASON = "isotropic contact"  # how an undefined angle whose contact has a centroid begins its reason
OUTLIER_FRACTION = 0.1         # contact regions smaller than this fraction of the largest are removed
DEPTH_CAP_MM = 1e6             # depths are capped far above any real indentation so sums cannot overflow
GAUSS_TRUNCATE = 4.0           # the Gaussian kernel's reach in standard deviations (scipy.ndimage's default)
CROSS_MOMENT_NOISE = 1e-7      # |sxy| below this fraction of sxx + syy is float32 rounding (angle shift < 1e-5 deg)
FEW_REGIONS = 8                # up to this many contact regions are sized one by one, more by bincount
FILTER_BLOCK_PX = 24           # output rows per filter block: small enough that OpenBLAS stays on one thread
_CROSS = ndimage.generate_binary_structure(2, 1)  # 4-connectivity (scipy.ndimage.label's default), built once


@dataclass(frozen=True)
class PoseParams:
    """Post-processing and PCA parameters of :func:`angle_from_image` (the paper's pipeline).

    Attributes:
        threshold_mm: pixels shallower than this are not contact, mm.
        sigma_mm: standard deviation of the Gaussian filter applied before PCA, mm (0: no filter).
        outlier_fraction: connected contact regions smaller than this fraction of the largest are removed.
        min_contact_px: fewer contact pixels than this after filtering: the angle is undefined.
        isotropy_limit: a minor/major eigenvalue ratio above this: the angle is undefined (round contact).
        background: "median" subtracts the image's median level first when it is positive (an image whose
            background is not zero, like the interpolation baselines' fitted offset of 0.14 mm, would otherwise
            count the whole pad as contact; contacts covering less than half the image are unaffected);
            "none" keeps the image as it is.
        aperture: "disc" takes the moments over a disc centred in the image (:func:`aperture_disc`, radius
            half the image's width less two filter widths: 9.4 mm on the 20 mm pad): a rod wider than the
            pad's clear width is cut by the square edges into a sheared band whose principal axis leans
            towards the diagonal (up to 1.7 deg on exact depth images, 5-8 deg on reconstructions of 5-8 mm
            bars at 55-65 deg), while a disc cuts any straight band symmetrically, so its axis is the rod's;
            contacts inside the disc are unaffected, and one with fewer than ``min_contact_px`` pixels
            inside it keeps the whole-image moments. "none": the whole image (the paper's pipeline). The
            contact's centroid and area are over the whole image either way.
    """

    threshold_mm: float = DEFAULT_THRESHOLD_MM
    sigma_mm: float = DEFAULT_SIGMA_MM
    outlier_fraction: float = OUTLIER_FRACTION
    min_contact_px: int = MIN_CONTACT_PX
    isotropy_limit: float = ISOTROPY_LIMIT
    background: str = "median"
    aperture: str = "disc"

    def __post_init__(self) -> None:
        if self.background not in ("median", "none"):
            raise ValueError(f"PoseParams.background must be 'median' or 'none', got {self.background!r}")
        if self.aperture not in ("disc", "none"):
            raise ValueError(f"PoseParams.aperture must be 'disc' or 'none', got {self.aperture!r}")
        checks = {"threshold_mm": self.threshold_mm >= 0, "sigma_mm": self.sigma_mm >= 0,
                  "outlier_fraction": 0 <= self.outlier_fraction <= 1, "min_contact_px": self.min_contact_px >= 1,
                  "isotropy_limit": 0 < self.isotropy_limit <= 1}
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (ok and math.isfinite(value)):
                raise ValueError(f"PoseParams.{name}: invalid value {value!r} (see the field's documentation)")


def wrap_axial(angle_rad: float | np.ndarray) -> float | np.ndarray:
    """Wrap an axial angle (period pi) to (-pi/2, pi/2]."""
    if type(angle_rad) is float:  # a scalar without numpy's overhead (Python's % is np.mod for floats)
        return -((-angle_rad + math.pi / 2) % math.pi) + math.pi / 2
    wrapped = -np.mod(-np.asarray(angle_rad, dtype=np.float64) + np.pi / 2, np.pi) + np.pi / 2
    return float(wrapped) if np.ndim(angle_rad) == 0 else wrapped


def remove_outliers(depth_mm: np.ndarray, *, threshold_mm: float = DEFAULT_THRESHOLD_MM,
                    min_fraction: float = OUTLIER_FRACTION) -> np.ndarray:
    """Zero the connected contact regions smaller than ``min_fraction`` of the largest (speckle, ghosts)."""
    # NaN/inf pixels are not contact; depths are capped far above any real indentation so sums cannot overflow
    d = np.nan_to_num(np.asarray(depth_mm, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0).clip(None, DEPTH_CAP_MM)
    labels, n = ndimage.label(d > threshold_mm)
    if n <= 1:
        return np.clip(d, 0.0, None)
    sizes = ndimage.sum_labels(np.ones_like(d), labels, index=np.arange(1, n + 1))
    keep = np.concatenate([[True], sizes >= min_fraction * sizes.max()])  # label 0 (below threshold) stays
    return np.where(keep[labels], np.clip(d, 0.0, None), 0.0)


def minus_background(depth_mm: np.ndarray) -> tuple[np.ndarray, float]:
    """The image less its median level when that level is positive (finite pixels only), and that level."""
    d = np.asarray(depth_mm, dtype=np.float64)
    finite = d[np.isfinite(d)]
    level = float(np.median(finite)) if finite.size else 0.0
    return (d - level, level) if level > 0 else (d, 0.0)


def angle_from_image(depth_mm: np.ndarray, *, pixel_mm: float = 0.1, threshold_mm: float = DEFAULT_THRESHOLD_MM,
                     sigma_mm: float = DEFAULT_SIGMA_MM, params: PoseParams | None = None) -> AngleEstimate:
    """Principal in-plane angle of the contact in a depth image (H, W), mm (float32 or float64).

    ``params`` (a :class:`PoseParams`) overrides ``threshold_mm`` and ``sigma_mm`` and sets the other limits.

    Raises:
        ValueError: ``depth_mm`` is not 2-D, or ``pixel_mm`` is not finite and > 0.
    """
    if np.ndim(depth_mm) != 2:
        raise ValueError(f"depth_mm: expected an (H, W) image, got shape {np.shape(depth_mm)}")
    pixel_mm = check_finite_scalar("pixel_mm", pixel_mm, low=0.0, low_open=True)
    p = params or PoseParams(threshold_mm=threshold_mm, sigma_mm=sigma_mm)
    d, level = _prepared(depth_mm, median=p.background == "median")
    sigma_px = p.sigma_mm / pixel_mm
    radius_px = int(GAUSS_TRUNCATE * sigma_px + 0.5) if sigma_px > 0 else 0  # as scipy.ndimage rounds it
    disc = aperture_disc(*d.shape, sigma_px, d.dtype.char) if p.aperture == "disc" and d.size else None
    if d.dtype == np.float32 and d.size and pose_kernel.available():
        m = pose_kernel.contact_moments(d, threshold_mm=p.threshold_mm, outlier_fraction=p.outlier_fraction,
                                        kernel=_gaussian_taps(sigma_px, radius_px), disc=disc,
                                        min_px=p.min_contact_px, pixel_mm=pixel_mm)
    else:
        m = _contact_moments(d, p, pixel_mm, sigma_px, radius_px, disc)
    if m.status != pose_kernel.OK:
        return _undefined(p, m.n_px, m.raw_px, level, pixel_mm)
    sxx, syy, sxy = m.sxx, m.syy, m.sxy
    if abs(sxy) <= CROSS_MOMENT_NOISE * (sxx + syy):
        # a contact symmetric about an axis, whose float32 filter output is symmetric only to rounding: it lands
        # exactly on 0 or on +pi/2 as the float64 pipeline puts it, not a rounding error either side of the wrap
        sxy = 0.0
    area = m.n_px * pixel_mm**2
    half_diff = 0.5 * (sxx - syy)
    radius = math.hypot(half_diff, sxy)
    major, minor = 0.5 * (sxx + syy) + radius, 0.5 * (sxx + syy) - radius
    ratio = minor / major if major > 0 else 1.0
    if ratio > p.isotropy_limit:
        return AngleEstimate(0.0, 0.0, False, m.centroid_mm, area, f"{ISOTROPIC_REASON} (eigenvalue ratio {ratio:.2f})")
    angle = wrap_axial(0.5 * math.atan2(2.0 * sxy, sxx - syy))
    return AngleEstimate(angle, min(max(1.0 - ratio, 0.0), 1.0), True, m.centroid_mm, area)


def _contact_moments(d: np.ndarray, p: PoseParams, pixel_mm: float, sigma_px: float, radius_px: int,
                     disc: np.ndarray | None) -> pose_kernel.ContactMoments:
    """What :func:`~tactile_manip.perception.pose_kernel.contact_moments` computes in C, in numpy (any dtype)."""
    contact = _kept_contact(d, p.threshold_mm, p.outlier_fraction)
    if contact is None:
        return pose_kernel.ContactMoments(pose_kernel.EMPTY, 0, 0, (0.0, 0.0), 0.0, 0.0, 0.0)
    (rows, cols), raw_px, removed = contact
    weights, (r0, c0) = _weights(d, rows, cols, removed, p.threshold_mm, sigma_px, radius_px)
    n_px = int(np.count_nonzero(weights > 0))  # (the comparison and a bool count beat a float count)
    if n_px < p.min_contact_px:
        return pose_kernel.ContactMoments(pose_kernel.TOO_SMALL, raw_px, n_px, (0.0, 0.0), 0.0, 0.0, 0.0)
    h, w = d.shape
    x = (np.arange(c0, c0 + weights.shape[1]) - (w - 1) / 2) * pixel_mm
    y = -(np.arange(r0, r0 + weights.shape[0]) - (h - 1) / 2) * pixel_mm
    windowed = _in_aperture(weights, r0, c0, disc, p.min_contact_px) if disc is not None else weights
    cx, cy, sxx, syy, sxy = _second_moments(windowed, x, y)
    if windowed is not weights:  # the centroid of the whole contact
        wt = weights.astype(np.float64)
        col, row = np.ones(wt.shape[0]) @ wt, wt @ np.ones(wt.shape[1])  # (BLAS: 2x faster than .sum(axis))
        total = float(col.sum())
        cx, cy = float(col @ x) / total, float(row @ y) / total
    return pose_kernel.ContactMoments(pose_kernel.OK, raw_px, n_px, (cx, cy), sxx, syy, sxy)


def _undefined(p: PoseParams, n_px: int, raw_px: int, level: float, pixel_mm: float) -> AngleEstimate:
    if raw_px == 0 and level > p.threshold_mm:
        reason = f"uniform contact: nothing stands above the image's background level ({level:.3g} mm)"
    elif raw_px == 0:
        reason = "empty contact"
    else:
        reason = f"contact too small ({n_px} px after filtering < {p.min_contact_px})"
    return AngleEstimate(0.0, 0.0, False, area_mm2=n_px * pixel_mm**2, reason=reason)


def _prepared(depth_mm: np.ndarray, *, median: bool) -> tuple[np.ndarray, float]:
    """The image with its positive median level removed (when ``median``), and that level: float32 when the
    image is float32 (a reconstruction: the fast path), otherwise float64 (the precision it came with).

    NaN and infinite pixels become 0 and depths are capped at ``DEPTH_CAP_MM`` as in :func:`remove_outliers`;
    negative pixels are left for the caller (only pixels above the threshold, and their neighbours, are read).
    A finite image, capped already, whose positive pixels are too few to lift the median above 0 (every
    reconstruction of a contact smaller than half the pad) takes the fast path: a cast and two counts.
    """
    a = np.asarray(depth_mm)
    dtype = np.float32 if a.dtype == np.float32 else np.float64
    a = a.astype(dtype, copy=False)
    if a.size and math.isfinite(float(a.min())) and math.isfinite(hi := float(a.max())) and hi <= DEPTH_CAP_MM:
        if not median or hi <= 0 or np.count_nonzero(a > 0) < (a.size + 1) // 2:
            return a, 0.0
        level = _median(a)
        if level <= 0:
            return a, 0.0
        return (a.astype(np.float64) - level).astype(dtype), level
    level = 0.0
    if median:
        a, level = minus_background(a)
    clean = np.nan_to_num(np.asarray(a, np.float64), nan=0.0, posinf=0.0, neginf=0.0).clip(None, DEPTH_CAP_MM)
    return clean.astype(dtype), level


def _median(a: np.ndarray) -> float:
    """The median of a finite array, as ``np.median`` of its float64 values gives it (without the cast).

    The middle order statistics are selected among the values in (lo, hi], two quantiles of a 1-in-16
    subsample (about a tenth of the pixels), after counting the values <= lo (a reconstruction's many exact
    zeros); when that window misses them, among all values.
    """
    flat, n = a.ravel(), a.size
    ranks = (n // 2,) if n % 2 else (n // 2 - 1, n // 2)
    if n >= 4096:
        sample = np.sort(flat[::16])
        lo, hi = sample[int(0.45 * sample.size)], sample[int(0.55 * sample.size)]
        below = int(np.count_nonzero(flat <= lo))
        window = flat[(flat > lo) & (flat <= hi)]
        if below <= ranks[0] and ranks[-1] < below + window.size:
            flat, ranks = window, tuple(r - below for r in ranks)
    part = np.partition(flat, ranks)
    return float(part[ranks[0]]) if len(ranks) == 1 else (float(part[ranks[0]]) + float(part[ranks[1]])) / 2


def _kept_contact(d: np.ndarray, threshold_mm: float, min_fraction: float):
    """The contact that survives :func:`remove_outliers`: its bounding box ((r0, r1), (c0, c1)) in pixels,
    its pixel count, and the removed regions as (mask, r0, c0) over the box of all contact (None: none
    removed); None when no pixel is above the threshold."""
    mask = d > threshold_mm
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    r0, r1, c0, c1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
    box = mask[r0:r1, c0:c1]
    labels, n = ndimage.label(box, _CROSS)  # the same regions as over the whole image
    if n <= 1:
        return ((r0, r1), (c0, c1)), int(np.count_nonzero(box)), None
    # a few regions (speckle beside one contact): a comparison per region beats bincount's int64 copy
    sizes = (np.array([np.count_nonzero(labels == k) for k in range(1, n + 1)]) if n <= FEW_REGIONS
             else np.bincount(labels.ravel(), minlength=n + 1)[1:])
    keep = sizes >= min_fraction * sizes.max()
    if keep.all():
        return ((r0, r1), (c0, c1)), int(sizes.sum()), None
    if np.count_nonzero(keep) == 1:  # the common case: one contact and some speckle
        kept = labels == int(np.argmax(keep)) + 1
    else:
        kept = np.concatenate([[False], keep]).take(labels)
    removed = box & ~kept
    rows, cols = np.flatnonzero(kept.any(axis=1)), np.flatnonzero(kept.any(axis=0))
    kept_rows, kept_cols = (r0 + int(rows[0]), r0 + int(rows[-1]) + 1), (c0 + int(cols[0]), c0 + int(cols[-1]) + 1)
    return (kept_rows, kept_cols), int(sizes[keep].sum()), (removed, r0, c0)


def _weights(d: np.ndarray, rows: tuple[int, int], cols: tuple[int, int], removed, threshold_mm: float,
             sigma_px: float, radius_px: int) -> tuple[np.ndarray, tuple[int, int]]:
    """``max(gaussian(d) - threshold, 0)`` over the kept contact's box plus ``radius_px`` (the only pixels
    where it can be > 0), in d's dtype, and the box's top-left pixel (row, col).

    The filter reads the box plus twice the radius: all the input any output pixel of the box sees. It is
    ``G_rows @ crop @ G_cols.T`` with banded matrices of the truncated, zero-padded (mode "constant") kernel.
    """
    h, w = d.shape
    reach = 2 * radius_px
    e0, e1, f0, f1 = max(rows[0] - reach, 0), min(rows[1] + reach, h), max(cols[0] - reach, 0), min(cols[1] + reach, w)
    crop = np.maximum(d[e0:e1, f0:f1], 0.0)
    if removed is not None:  # zero the removed regions where they overlap the crop
        mask, r0, c0 = removed
        a0, a1 = max(e0, r0), min(e1, r0 + mask.shape[0])
        b0, b1 = max(f0, c0), min(f1, c0 + mask.shape[1])
        if a0 < a1 and b0 < b1:
            crop[a0 - e0:a1 - e0, b0 - f0:b1 - f0][mask[a0 - r0:a1 - r0, b0 - c0:b1 - c0]] = 0.0
    if radius_px == 0:
        out, (o0, p0) = crop, (e0, f0)
    else:
        o0, o1 = max(rows[0] - radius_px, 0), min(rows[1] + radius_px, h)
        p0, p1 = max(cols[0] - radius_px, 0), min(cols[1] + radius_px, w)
        g_rows, g_cols = (_gaussian_matrix(n, sigma_px, radius_px, crop.dtype.char) for n in (h, w))
        along_cols = _banded_rows(g_rows, crop, e0, (o0, o1), radius_px)
        out = _banded_rows(g_cols, along_cols.T, f0, (p0, p1), radius_px).T
    out -= out.dtype.type(threshold_mm)
    return np.maximum(out, 0.0, out=out), (o0, p0)


def _in_aperture(weights: np.ndarray, r0: int, c0: int, disc: np.ndarray, min_px: int) -> np.ndarray:
    """``weights`` (a box at pixel (r0, c0) of the image) times the image's aperture ``disc``, unless fewer than
    ``min_px`` of its pixels are left (then unchanged). A box inside the disc (every contact smaller than about
    65 % of the pad's width) is returned as it is, without a copy."""
    bh, bw = weights.shape
    if min(disc[r0, c0], disc[r0, c0 + bw - 1], disc[r0 + bh - 1, c0], disc[r0 + bh - 1, c0 + bw - 1]) == 1:
        return weights  # a disc is convex: its four corners inside, so is the box
    windowed = weights * disc[r0:r0 + bh, c0:c0 + bw]
    return windowed if np.count_nonzero(windowed > 0) >= min_px else weights


@lru_cache(maxsize=8)
def aperture_disc(h: int, w: int, sigma_px: float, dtype: str = "d") -> np.ndarray:
    """(h, w) weights of the moments' aperture (read-only): 1 inside the centred disc of radius
    ``min(h, w) / 2 - 2 sigma_px`` pixels, 0 outside, the pixel's covered fraction on its edge (a hard edge's
    staircase biases a band's axis by up to 0.1 deg). The margin of two filter widths keeps the disc off the
    image border, where the filter's zero padding would thin a band on one side (0.13 deg without it)."""
    y, x = np.ogrid[:h, :w]
    radius = max(min(h, w) / 2 - 2 * sigma_px, 0.5)
    disc = np.clip(radius + 0.5 - np.hypot(x - (w - 1) / 2, y - (h - 1) / 2), 0.0, 1.0).astype(dtype)
    disc.setflags(write=False)
    return disc


def _banded_rows(g: np.ndarray, a: np.ndarray, a0: int, rows: tuple[int, int], radius_px: int) -> np.ndarray:
    """Rows ``rows`` of ``g @ A`` for a banded ``g`` (n, n) of half-width ``radius_px``, where ``a`` holds
    the rows ``a0 ..`` of A (zero elsewhere): in blocks of output rows, each reading only the input rows
    within its band (a fifth of the dense product's work on a 200-pixel contact; blocks of M*N*K < 2.6e5 also
    keep OpenBLAS on one thread, where two threads were slower here)."""
    out = np.empty((rows[1] - rows[0], a.shape[1]), a.dtype)
    for s in range(rows[0], rows[1], FILTER_BLOCK_PX):
        t = min(s + FILTER_BLOCK_PX, rows[1])
        lo, hi = max(s - radius_px, a0), min(t + radius_px, a0 + a.shape[0])
        np.matmul(g[s:t, lo:hi], a[lo - a0:hi - a0], out=out[s - rows[0]:t - rows[0]])
    return out


@lru_cache(maxsize=16)
def _gaussian_matrix(n: int, sigma_px: float, radius_px: int, dtype: str) -> np.ndarray:
    """(n, n) matrix (of ``dtype``) of a 1-D Gaussian filter over n pixels with zeros beyond the ends: row i holds
    the kernel centred on pixel i (the kernel as ``scipy.ndimage.gaussian_filter`` builds it)."""
    x = np.arange(-radius_px, radius_px + 1)
    kernel = np.exp(-0.5 / (sigma_px * sigma_px) * x**2)
    kernel = kernel / kernel.sum()
    g = np.zeros((n, n + 2 * radius_px))
    idx = np.arange(n)
    g[idx[:, None], idx[:, None] + np.arange(2 * radius_px + 1)] = kernel
    out = np.ascontiguousarray(g[:, radius_px:radius_px + n], dtype=dtype)
    out.setflags(write=False)
    return out


@lru_cache(maxsize=16)
def _gaussian_taps(sigma_px: float, radius_px: int) -> np.ndarray:
    """The float32 taps of the filter (2 radius_px + 1) that :func:`_gaussian_matrix` puts in its rows
    (``[1.0]``: no filter), for the C kernel."""
    if radius_px == 0:
        return np.ones(1, np.float32)
    taps = np.ascontiguousarray(_gaussian_matrix(2 * radius_px + 1, sigma_px, radius_px, "f")[radius_px])
    taps.setflags(write=False)
    return taps


def _second_moments(weights: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[float, float, float, float, float]:
    """Centroid (cx, cy) and central second moments (sxx, syy, sxy) of ``weights`` (h, w) at pixel
    coordinates ``x`` (w,) and ``y`` (h,), mm: a column sum and one product with (1, x - cx), float64."""
    wt = np.asarray(weights, np.float64)
    col = np.ones(wt.shape[0]) @ wt  # (BLAS: 2x faster than .sum(axis=0))
    total = float(col.sum())
    cx = float(col @ x) / total
    dx = x - cx
    rows = wt @ np.stack([np.ones_like(dx), dx], axis=1)  # (h, 2): row sums and row sums of w * (x - cx)
    cy = float(rows[:, 0] @ y) / total
    dy = y - cy
    sxx, syy = float(col @ (dx * dx)) / total, float(rows[:, 0] @ (dy * dy)) / total
    return cx, cy, sxx, syy, float(dy @ rows[:, 1]) / total
