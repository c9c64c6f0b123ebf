"""From a depth image to the in-plane angle of the contact: outlier removal, Gaussian filter, PCA.

Pure functions over (H, W) depth images in mm (pixel (0, 0) at the pad's (-x, +y) corner). The angle is
the principal axis of the depth-weighted second moments of the contact, counter-clockwise from +x and
wrapped to (-pi/2, pi/2]; its confidence is ``1 - lambda_minor / lambda_major``. Empty, tiny or isotropic
contacts give ``defined=False`` with a reason, never NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from tactile_manip.checks import check_finite_scalar
from tactile_manip.types import AngleEstimate

DEFAULT_THRESHOLD_MM = 0.1     # pixels shallower than this are not contact
DEFAULT_SIGMA_MM = 0.3         # Gaussian filter before PCA
MIN_CONTACT_PX = 20            # fewer contact pixels: angle undefined
ISOTROPY_LIMIT = 0.9           # minor/major eigenvalue ratio above this: angle undefined
OUTLIER_FRACTION = 0.1         # contact regions smaller than this fraction of the largest are removed


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
    """

    threshold_mm: float = DEFAULT_THRESHOLD_MM
    sigma_mm: float = DEFAULT_SIGMA_MM
    outlier_fraction: float = OUTLIER_FRACTION
    min_contact_px: int = MIN_CONTACT_PX
    isotropy_limit: float = ISOTROPY_LIMIT
    background: str = "median"

    def __post_init__(self) -> None:
        if self.background not in ("median", "none"):
            raise ValueError(f"PoseParams.background must be 'median' or 'none', got {self.background!r}")
        checks = {"threshold_mm": self.threshold_mm >= 0, "sigma_mm": self.sigma_mm >= 0,
                  "outlier_fraction": 0 <= self.outlier_fraction <= 1, "min_contact_px": self.min_contact_px >= 1,
                  "isotropy_limit": 0 < self.isotropy_limit <= 1}
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (ok and math.isfinite(value)):
                raise ValueError(f"PoseParams.{name}: invalid value {value!r} (see the field's documentation)")


def wrap_axial(angle_rad: float | np.ndarray) -> float | np.ndarray:
    """Wrap an axial angle (period pi) to (-pi/2, pi/2]."""
    wrapped = -np.mod(-np.asarray(angle_rad, dtype=np.float64) + np.pi / 2, np.pi) + np.pi / 2
    return float(wrapped) if np.ndim(angle_rad) == 0 else wrapped


def remove_outliers(depth_mm: np.ndarray, *, threshold_mm: float = DEFAULT_THRESHOLD_MM,
                    min_fraction: float = OUTLIER_FRACTION) -> np.ndarray:
    """Zero the connected contact regions smaller than ``min_fraction`` of the largest (speckle, ghosts)."""
    # NaN/inf pixels are not contact; depths are capped far above any real indentation so sums cannot overflow
    d = np.nan_to_num(np.asarray(depth_mm, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0).clip(None, 1e6)
    labels, n = ndimage.label(d > threshold_mm)
    if n <= 1:
        return np.clip(d, 0.0, None)
    sizes = ndimage.sum_labels(np.ones_like(d), labels, index=np.arange(1, n + 1))
    keep = np.concatenate([[True], sizes >= min_fraction * sizes.max()])  # label 0 (below threshold) stays
    return np.where(keep[labels], np.clip(d, 0.0, None), 0.0)


def _minus_background(depth_mm: np.ndarray) -> tuple[np.ndarray, float]:
    """The image less its median level when that level is positive (finite pixels only), and that level."""
    d = np.asarray(depth_mm, dtype=np.float64)
    finite = d[np.isfinite(d)]
    level = float(np.median(finite)) if finite.size else 0.0
    return (d - level, level) if level > 0 else (d, 0.0)


def angle_from_image(depth_mm: np.ndarray, *, pixel_mm: float = 0.1, threshold_mm: float = DEFAULT_THRESHOLD_MM,
                     sigma_mm: float = DEFAULT_SIGMA_MM, params: PoseParams | None = None) -> AngleEstimate:
    """Principal in-plane angle of the contact in a depth image (H, W), mm.

    ``params`` (a :class:`PoseParams`) overrides ``threshold_mm`` and ``sigma_mm`` and sets the other limits.

    Raises:
        ValueError: ``depth_mm`` is not 2-D, or ``pixel_mm`` is not finite and > 0.
    """
    if np.ndim(depth_mm) != 2:
        raise ValueError(f"depth_mm: expected an (H, W) image, got shape {np.shape(depth_mm)}")
    pixel_mm = check_finite_scalar("pixel_mm", pixel_mm, low=0.0, low_open=True)
    p = params or PoseParams(threshold_mm=threshold_mm, sigma_mm=sigma_mm)
    threshold_mm, sigma_mm = p.threshold_mm, p.sigma_mm
    level = 0.0
    if p.background == "median":
        depth_mm, level = _minus_background(depth_mm)
    d = remove_outliers(depth_mm, threshold_mm=threshold_mm, min_fraction=p.outlier_fraction)
    raw_px = int(np.count_nonzero(d > threshold_mm))
    if sigma_mm > 0:
        d = ndimage.gaussian_filter(d, sigma_mm / pixel_mm, mode="constant")
    weights = np.where(d > threshold_mm, d - threshold_mm, 0.0)
    n_px = int(np.count_nonzero(weights))
    area = n_px * pixel_mm**2
    if n_px < p.min_contact_px:
        if raw_px == 0 and level > threshold_mm:
            reason = f"uniform contact: nothing stands above the image's background level ({level:.3g} mm)"
        elif raw_px == 0:
            reason = "empty contact"
        else:
            reason = f"contact too small ({n_px} px after filtering < {p.min_contact_px})"
        return AngleEstimate(0.0, 0.0, False, area_mm2=area, reason=reason)
    h, w = d.shape
    x = (np.arange(w) - (w - 1) / 2) * pixel_mm
    y = -(np.arange(h) - (h - 1) / 2) * pixel_mm
    total = weights.sum()
    cx = float((weights.sum(0) * x).sum() / total)
    cy = float((weights.sum(1) * y).sum() / total)
    dx, dy = x[None, :] - cx, y[:, None] - cy
    sxx = float((weights * dx * dx).sum() / total)
    syy = float((weights * dy * dy).sum() / total)
    sxy = float((weights * dx * dy).sum() / total)
    half_diff = 0.5 * (sxx - syy)
    radius = math.hypot(half_diff, sxy)
    major, minor = 0.5 * (sxx + syy) + radius, 0.5 * (sxx + syy) - radius
    ratio = minor / major if major > 0 else 1.0
    if ratio > p.isotropy_limit:
        return AngleEstimate(0.0, 0.0, False, (cx, cy), area, f"isotropic contact (eigenvalue ratio {ratio:.2f})")
    angle = wrap_axial(0.5 * math.atan2(2.0 * sxy, sxx - syy))
    return AngleEstimate(angle, float(np.clip(1.0 - ratio, 0.0, 1.0)), True, (cx, cy), area)
