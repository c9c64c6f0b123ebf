"""Image metrics: PSNR/SSIM against closed forms and invariants, FD-DCT against the Gaussian Frechet distance."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg

from tactile_manip.evaluation.metrics import (DEPTH_RANGE_MM, dct_features, fd_dct, frechet_distance, psnr,
                                              ssim)


def _blob_images(rng: np.random.Generator, n: int, size: int = 32) -> np.ndarray:
    """(n, size, size) smooth contacts (Gaussian bumps, 0.2-1.5 mm deep) at random places on an empty pad."""
    yy, xx = np.mgrid[:size, :size].astype(np.float64)
    out = np.zeros((n, size, size))
    for i in range(n):
        cy, cx = rng.uniform(8, size - 8, 2)
        r = rng.uniform(2.0, 4.0)
        out[i] = rng.uniform(0.2, 1.5) * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * r * r))
    return out


# ---------------------------------------------------------------- PSNR


@pytest.mark.parametrize("error_mm", [0.01, 0.1, 0.5, 2.0])
def test_psnr_of_a_constant_error_is_the_closed_form(error_mm: float) -> None:
    truth = _blob_images(np.random.default_rng(0), 1)[0]
    expected = 10 * np.log10(DEPTH_RANGE_MM**2 / error_mm**2)
    assert psnr(truth + error_mm, truth) == pytest.approx(expected, abs=1e-9)
    assert psnr(truth - error_mm, truth) == pytest.approx(expected, abs=1e-9)


def test_psnr_of_identical_images_is_plus_infinity() -> None:
    truth = _blob_images(np.random.default_rng(1), 3)
    values = psnr(truth, truth)
    assert values.shape == (3,)
    assert np.all(np.isposinf(values))


def test_psnr_batch_is_per_image() -> None:
    truth = _blob_images(np.random.default_rng(2), 2)
    pred = truth + np.array([0.1, 0.2])[:, None, None]
    np.testing.assert_allclose(psnr(pred, truth), [psnr(pred[0], truth[0]), psnr(pred[1], truth[1])])
    np.testing.assert_allclose(psnr(pred, truth), 10 * np.log10(4.0 / np.array([0.01, 0.04])))


def test_data_range_is_the_fixed_2_mm_not_the_image_maximum() -> None:
    rng = np.random.default_rng(3)
    truth = _blob_images(rng, 1)[0]
    pred = truth + rng.normal(0, 0.05, truth.shape)
    assert DEPTH_RANGE_MM == 2.0
    assert psnr(pred, truth) == psnr(pred, truth, data_range=2.0)
    # A deeper contact (larger image maximum) with the same error keeps the same PSNR: the range is fixed.
    assert psnr(pred + 1.0, truth + 1.0) == pytest.approx(psnr(pred, truth), abs=1e-9)
    # Changing the range shifts PSNR by 20 log10 of the ratio.
    for new_range in (1.0, 4.0, 2.55):
        shift = 20 * np.log10(new_range / DEPTH_RANGE_MM)
        assert psnr(pred, truth, data_range=new_range) - psnr(pred, truth) == pytest.approx(shift, abs=1e-9)


# ---------------------------------------------------------------- SSIM


def test_ssim_of_identical_images_is_one() -> None:
    truth = _blob_images(np.random.default_rng(4), 3)
    np.testing.assert_allclose(ssim(truth, truth), 1.0, atol=1e-12)
    assert ssim(truth[0], truth[0]) == pytest.approx(1.0, abs=1e-12)


def test_ssim_is_symmetric_and_bounded() -> None:
    rng = np.random.default_rng(5)
    truth = _blob_images(rng, 6)
    preds = [truth + rng.normal(0, 0.3, truth.shape),      # noisy
             truth[::-1],                                 # other images
             1.5 - truth,                                 # anti-correlated: negative SSIM
             rng.uniform(-2, 2, truth.shape)]             # unrelated noise
    for pred in preds:
        ab, ba = ssim(pred, truth), ssim(truth, pred)
        np.testing.assert_allclose(ab, ba, rtol=0, atol=1e-12)
        assert np.all((ab >= -1.0) & (ab <= 1.0))
    assert np.all(ssim(1.5 - truth, truth) < 0)


def test_ssim_of_a_zero_prediction_on_a_mostly_empty_truth_is_high() -> None:
    # Where both images are 0, the SSIM map is (c1 c2) / (c1 c2) = 1 exactly, and a small contact leaves most of
    # the image background: SSIM rewards predicting nothing. This is why reports pair SSIM with PSNR and FD-DCT.
    truth = np.zeros((64, 64))
    truth[30:34, 30:34] = 1.0
    zero = np.zeros_like(truth)
    value = float(ssim(zero, truth))
    assert 0.8 < value < 1.0
    # A full-pad contact predicted as zero is a poor SSIM.
    assert float(ssim(zero, np.ones_like(truth))) < 0.01


def test_ssim_decreases_with_noise() -> None:
    rng = np.random.default_rng(6)
    truth = _blob_images(rng, 1)[0]
    noise = rng.normal(0, 1, truth.shape)
    values = [float(ssim(truth + s * noise, truth)) for s in (0.0, 0.02, 0.1, 0.5)]
    assert values == sorted(values, reverse=True)
    assert values[0] == pytest.approx(1.0) and values[-1] < 0.5


# ---------------------------------------------------------------- input checks


@pytest.mark.parametrize("metric", [psnr, ssim])
def test_shape_mismatch_raises(metric) -> None:
    with pytest.raises(ValueError, match=r"\(8, 8\) and \(8, 9\)"):
        metric(np.zeros((8, 8)), np.zeros((8, 9)))
    with pytest.raises(ValueError, match="shape"):
        metric(np.zeros(64), np.zeros(64))


@pytest.mark.parametrize("metric", [psnr, ssim])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_images_raise(metric, bad: float) -> None:
    img = np.zeros((16, 16))
    broken = img.copy()
    broken[3, 4] = bad
    with pytest.raises(ValueError, match="NaN or infinite"):
        metric(broken, img)
    with pytest.raises(ValueError, match="NaN or infinite"):
        metric(img, broken)


@pytest.mark.parametrize("metric", [psnr, ssim])
def test_float32_and_float64_inputs_agree(metric) -> None:
    rng = np.random.default_rng(7)
    truth = _blob_images(rng, 4)
    pred = np.clip(truth + rng.normal(0, 0.05, truth.shape), 0, None)
    v64 = metric(pred, truth)
    v32 = metric(pred.astype(np.float32), truth.astype(np.float32))
    np.testing.assert_allclose(v32, v64, rtol=1e-5, atol=1e-5)


# ---------------------------------------------------------------- FD-DCT


def test_dct_features_shape_and_dc_term() -> None:
    imgs = _blob_images(np.random.default_rng(8), 5, size=24)
    feats = dct_features(imgs)
    assert feats.shape == (5, 64)
    assert dct_features(imgs, size=4).shape == (5, 16)
    # Orthonormal DCT-II: the first coefficient is the image sum / sqrt(H W).
    np.testing.assert_allclose(feats[:, 0], imgs.sum(axis=(1, 2)) / 24.0, rtol=1e-12)
    with pytest.raises(ValueError, match=r"\(N, H, W\)"):
        dct_features(imgs[0])


def test_fd_dct_of_identical_sets_is_zero() -> None:
    imgs = _blob_images(np.random.default_rng(9), 100)
    assert fd_dct(imgs, imgs) == pytest.approx(0.0, abs=1e-6)


def test_fd_dct_of_a_depth_offset_is_the_closed_form() -> None:
    # Adding c mm to every pixel moves only the DC feature, by c * sqrt(H W); covariances are unchanged, so
    # FD = (c sqrt(H W))^2 = c^2 H W.
    imgs = _blob_images(np.random.default_rng(10), 100)
    for c in (0.01, 0.05, 0.2):
        assert fd_dct(imgs + c, imgs) == pytest.approx(c * c * imgs[0].size, rel=1e-4, abs=1e-6)


def test_fd_dct_grows_with_a_spatial_shift() -> None:
    imgs = _blob_images(np.random.default_rng(11), 100)
    values = [fd_dct(np.roll(imgs, k, axis=2), imgs) for k in (1, 2, 4, 6)]
    assert values[0] > 1e-3
    assert values == sorted(values)


def test_frechet_distance_matches_the_gaussian_closed_form() -> None:
    rng = np.random.default_rng(12)
    mu_a, mu_b = np.array([0.0, 1.0, -1.0]), np.array([0.5, 0.0, -1.0])
    l_a = np.array([[1.0, 0, 0], [0.3, 0.8, 0], [-0.2, 0.1, 0.5]])
    l_b = np.array([[0.6, 0, 0], [0.0, 1.2, 0], [0.4, -0.3, 0.9]])
    cov_a, cov_b = l_a @ l_a.T, l_b @ l_b.T
    expected = float(np.sum((mu_a - mu_b) ** 2)
                     + np.trace(cov_a + cov_b - 2 * np.real(linalg.sqrtm(cov_a @ cov_b))))
    a = rng.multivariate_normal(mu_a, cov_a, 20000)
    b = rng.multivariate_normal(mu_b, cov_b, 20000)
    assert frechet_distance(a, b) == pytest.approx(expected, rel=0.05)
    assert frechet_distance(a, b) == pytest.approx(frechet_distance(b, a), rel=1e-6)
    assert frechet_distance(a, a) == pytest.approx(0.0, abs=1e-8)


def test_frechet_distance_rejects_bad_feature_sets() -> None:
    with pytest.raises(ValueError, match="N >= 2"):
        frechet_distance(np.zeros((1, 3)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match=r"\(5, 3\) and \(5, 4\)"):
        frechet_distance(np.zeros((5, 3)), np.zeros((5, 4)))
