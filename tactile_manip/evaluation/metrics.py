"""Image quality metrics for depth images, with a stated data range used everywhere.

PSNR and SSIM need a data range ``L``. Depth images are in millimetres and the DTact-style VBTS saturates at
1.92 mm, so depth datasets state ``L = DEPTH_RANGE_MM = 2.0`` mm (the default here) for every image, every
method and every report; a dataset in another unit states its own (``ImageSpec.data_range``), and evaluation
passes it. Never the per-image maximum, which would reward predicting noise on empty images. SSIM follows Wang et al. (2004):
11x11 Gaussian window with sigma 1.5 px, ``K1 = 0.01``, ``K2 = 0.03``, averaged over the image minus a
5-pixel border.

The paper's FID needs ImageNet Inception weights, which cannot be downloaded here. :func:`frechet_distance`
computes the Frechet distance between Gaussians fitted to features; :func:`dct_features` is our fixed,
documented feature space (the 8x8 lowest 2-D DCT-II coefficients of each image, orthonormal, in mm), and the
result is reported as ``FD-DCT``, never as FID. An Inception network exported to ONNX can be supplied by the
user to compute a real FID (see ``tactile_manip.evaluation.images``).
"""

from __future__ import annotations

import numpy as np
from scipy import fft, linalg, ndimage

DEPTH_RANGE_MM = 2.0
SSIM_SIGMA_PX = 1.5
SSIM_K1, SSIM_K2 = 0.01, 0.03
_BORDER_PX = 5
MAX_ABS_MM = 1e50  # larger |depth| is refused: SSIM multiplies four depths, which overflows near 1e77


def _pair(pred: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(pred, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if p.shape != t.shape or p.ndim not in (2, 3):
        raise ValueError(f"expected two (H, W) or (N, H, W) arrays of one shape, got {p.shape} and {t.shape}")
    if not (np.isfinite(p).all() and np.isfinite(t).all()):
        raise ValueError("images contain NaN or infinite values")
    if max(np.abs(p).max(initial=0.0), np.abs(t).max(initial=0.0)) > MAX_ABS_MM:
        raise ValueError(f"images contain values beyond +-{MAX_ABS_MM:g} mm: not depth images in mm (check the "
                         "units); SSIM's fourth powers would overflow to NaN")
    return (p[None], t[None]) if p.ndim == 2 else (p, t)


def psnr(pred: np.ndarray, truth: np.ndarray, *, data_range: float = DEPTH_RANGE_MM) -> np.ndarray:
    """Per-image PSNR in dB, (N,) (or a scalar array for one image). Identical images give +inf."""
    p, t = _pair(pred, truth)
    mse = np.mean((p - t) ** 2, axis=(1, 2))
    with np.errstate(divide="ignore"):
        out = 10.0 * np.log10(data_range**2 / mse)
    return out if np.ndim(pred) == 3 else out[0]


def ssim(pred: np.ndarray, truth: np.ndarray, *, data_range: float = DEPTH_RANGE_MM) -> np.ndarray:
    """Per-image mean SSIM in [-1, 1], (N,) (or a scalar array for one image)."""
    p, t = _pair(pred, truth)
    c1, c2 = (SSIM_K1 * data_range) ** 2, (SSIM_K2 * data_range) ** 2
    blur = lambda a: ndimage.gaussian_filter(a, sigma=(0, SSIM_SIGMA_PX, SSIM_SIGMA_PX), truncate=3.5)  # noqa: E731
    mu_p, mu_t = blur(p), blur(t)
    var_p = blur(p * p) - mu_p**2
    var_t = blur(t * t) - mu_t**2
    cov = blur(p * t) - mu_p * mu_t
    s = ((2 * mu_p * mu_t + c1) * (2 * cov + c2)) / ((mu_p**2 + mu_t**2 + c1) * (var_p + var_t + c2))
    b = _BORDER_PX
    out = s[:, b:-b, b:-b].mean(axis=(1, 2)) if min(s.shape[1:]) > 2 * b else s.mean(axis=(1, 2))
    return out if np.ndim(pred) == 3 else out[0]


def dct_features(images: np.ndarray, *, size: int = 8) -> np.ndarray:
    """(N, H, W) images in mm -> (N, size*size) lowest-frequency orthonormal 2-D DCT-II coefficients."""
    imgs = np.asarray(images, dtype=np.float64)
    if imgs.ndim != 3:
        raise ValueError(f"expected (N, H, W) images, got shape {imgs.shape}")
    coeffs = fft.dctn(imgs, type=2, axes=(1, 2), norm="ortho")
    return coeffs[:, :size, :size].reshape(len(imgs), -1)


def frechet_distance(feat_a: np.ndarray, feat_b: np.ndarray) -> float:
    """Frechet distance between Gaussians fitted to two feature sets (N, D) and (M, D)."""
    a, b = np.asarray(feat_a, np.float64), np.asarray(feat_b, np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or min(len(a), len(b)) < 2:
        raise ValueError(f"expected two (N, D) feature sets with N >= 2, got {a.shape} and {b.shape}")
    mu_a, mu_b = a.mean(0), b.mean(0)
    cov_a, cov_b = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    covmean = linalg.sqrtm(cov_a @ cov_b)
    covmean = np.real(covmean)
    value = float(np.sum((mu_a - mu_b) ** 2) + np.trace(cov_a + cov_b - 2.0 * covmean))
    return max(value, 0.0)


def fd_dct(pred: np.ndarray, truth: np.ndarray) -> float:
    """FD-DCT: the Frechet distance of :func:`dct_features` between predictions and ground truth."""
    return frechet_distance(dct_features(pred), dct_features(truth))
