"""The pose pipeline as first written: float64 passes over the whole image (the reference of the fast one).

:func:`reference_angle_from_image` is the paper's post-processing and PCA exactly as the project first
implemented it (median background, :func:`~tactile_manip.perception.pose.remove_outliers` over the whole
image, a full-image Gaussian filter, moments over every pixel, all in float64), with the moments' aperture
(``PoseParams.aperture``) added in the same plain form. It is kept as
the definition :func:`~tactile_manip.perception.pose.angle_from_image` (which crops to the contact and runs
in float32) is checked against: in tests/perception/test_pose_fast.py on synthetic images and in
``python -m benchmarks.check_pose_parity`` on the shipped model's reconstructions of the test split.
It takes about 10x longer; do not use it in a control loop.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from tactile_manip.checks import check_finite_scalar
from tactile_manip.perception.pose import (DEFAULT_SIGMA_MM, DEFAULT_THRESHOLD_MM, PoseParams, aperture_disc,
                                           minus_background, remove_outliers, wrap_axial)
from tactile_manip.types import AngleEstimate


def reference_angle_from_image(depth_mm: np.ndarray, *, pixel_mm: float = 0.1,
                               threshold_mm: float = DEFAULT_THRESHOLD_MM, sigma_mm: float = DEFAULT_SIGMA_MM,
                               params: PoseParams | None = None) -> AngleEstimate:
    """Principal in-plane angle of the contact in a depth image (H, W), mm: same contract as
    :func:`~tactile_manip.perception.pose.angle_from_image`."""
    if np.ndim(depth_mm) != 2:
        raise ValueError(f"depth_mm: expected an (H, W) image, got shape {np.shape(depth_mm)}")
    pixel_mm = check_finite_scalar("pixel_mm", pixel_mm, low=0.0, low_open=True)
    p = params or PoseParams(threshold_mm=threshold_mm, sigma_mm=sigma_mm)
    threshold_mm, sigma_mm = p.threshold_mm, p.sigma_mm
    level = 0.0
    if p.background == "median":
        depth_mm, level = minus_background(depth_mm)
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
    centroid = (float((weights.sum(0) * x).sum() / total), float((weights.sum(1) * y).sum() / total))
    if p.aperture == "disc":  # the moments over the largest centred disc when it holds enough of the contact
        windowed = weights * aperture_disc(h, w, sigma_mm / pixel_mm)
        if np.count_nonzero(windowed) >= p.min_contact_px:
            weights = windowed
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
        return AngleEstimate(0.0, 0.0, False, centroid, area, f"isotropic contact (eigenvalue ratio {ratio:.2f})")
    angle = wrap_axial(0.5 * math.atan2(2.0 * sxy, sxx - syy))
    return AngleEstimate(angle, float(np.clip(1.0 - ratio, 0.0, 1.0)), True, centroid, area)
