"""Stability of the pose (``angle_from_image``) and the image metrics on hard depth images.

Images here have the real format: (200, 200) over the 20 mm pad, 0.1 mm/px, float32 as the reconstructors
return them (and float64 for the agreement checks). Expected: an angle within a stated tolerance, or
``defined=False`` with a named reason, or a ``ValueError`` naming the argument; never NaN.

Already covered in tests/perception/test_pose.py on (100, 100) float64 images: an empty image, one pixel, an
isotropic disc, bars at +-90 / +-89.9 / 90.1 degrees, NaN/inf pixels, a saturated bar, 200 random images and
arbitrary float arrays never giving NaN, and float32 against float64 on one image. In
tests/perception/test_metrics.py: PSNR/SSIM on float32 against float64 noisy blobs and NaN/inf images.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from checks import assert_sane_estimate

from tactile_manip.evaluation.metrics import DEPTH_RANGE_MM, MAX_ABS_MM, psnr, ssim
from tactile_manip.perception.pose import angle_from_image, wrap_axial
from tactile_manip.types import AngleEstimate

PIXEL_MM = 0.1
SIZE_PX = 200
SATURATION_MM = 1.92             # the DTact-style VBTS saturates here
BORDER_TOLERANCE_DEG = 0.5       # a bar running off the image edge (measured worst: 0.21 degrees)
WRAP_TOLERANCE_DEG = 0.05        # a long thin bar at the +-90 degree seam (measured: 0.002 degrees)
F32_ANGLE_TOL_RAD = 1e-6         # float32 against float64 images: angle (measured: 6e-12 rad)
F32_CONFIDENCE_TOL = 1e-6        # and confidence


def _pad_xy() -> tuple[np.ndarray, np.ndarray]:
    c = (np.arange(SIZE_PX) - (SIZE_PX - 1) / 2) * PIXEL_MM
    return c[None, :], -c[:, None]


def bar(angle_rad: float, *, length_mm: float = 6.0, width_mm: float = 1.0, depth_mm: float = 1.0,
        centre_mm: tuple[float, float] = (0.0, 0.0), edge_mm: float = 0.2) -> np.ndarray:
    """(200, 200) float64 depth image of a flat-bottomed bar at ``angle_rad`` (CCW from +x), soft edges."""
    x, y = _pad_xy()
    dx, dy = x - centre_mm[0], y - centre_mm[1]
    along = dx * math.cos(angle_rad) + dy * math.sin(angle_rad)
    across = -dx * math.sin(angle_rad) + dy * math.cos(angle_rad)
    ramp = lambda half, u: np.clip((half - np.abs(u)) / edge_mm + 0.5, 0.0, 1.0)  # noqa: E731
    return depth_mm * ramp(length_mm / 2, along) * ramp(width_mm / 2, across)


def _axial_error_deg(a_rad: float, b_rad: float) -> float:
    return abs(math.degrees(wrap_axial(a_rad - b_rad)))


def _estimate(img: np.ndarray) -> AngleEstimate:
    est = angle_from_image(img, pixel_mm=PIXEL_MM)
    assert_sane_estimate(est)
    return est


# ---------------------------------------------------------------- degenerate images


def _one_pixel(row: int, col: int) -> np.ndarray:
    img = np.zeros((SIZE_PX, SIZE_PX), np.float32)
    img[row, col] = SATURATION_MM
    return img


def _disc(radius_mm: float = 3.0) -> np.ndarray:
    x, y = _pad_xy()
    return np.clip(1.0 - (x * x + y * y) / radius_mm**2, 0.0, None).astype(np.float32)


DEGENERATE = {
    "empty": (np.zeros((SIZE_PX, SIZE_PX), np.float32), "empty contact"),
    "below threshold": (np.full((SIZE_PX, SIZE_PX), 0.05, np.float32), "empty contact"),
    "no pixels": (np.zeros((0, 0), np.float32), "empty contact"),
    "one pixel, centre": (_one_pixel(100, 100), "too small"),
    "one pixel, corner": (_one_pixel(0, 0), "too small"),
    "one pixel, edge": (_one_pixel(199, 57), "too small"),
    "a 1x1 image": (np.ones((1, 1), np.float32), "uniform contact"),
    "isotropic disc": (_disc(), "isotropic"),
    # a uniformly deep image is all background (PoseParams.background = "median")
    "saturated everywhere": (np.full((SIZE_PX, SIZE_PX), SATURATION_MM, np.float32), "uniform contact"),
    "float32 maximum everywhere": (np.full((SIZE_PX, SIZE_PX), np.finfo(np.float32).max, np.float32), "uniform contact"),
    "NaN everywhere": (np.full((SIZE_PX, SIZE_PX), np.nan, np.float32), "empty contact"),
}


@pytest.mark.parametrize("case", list(DEGENERATE))
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_degenerate_images_are_undefined_with_a_reason(case, dtype):
    img, reason = DEGENERATE[case]
    est = _estimate(img.astype(dtype))
    assert not est.defined and reason in est.reason
    assert est.angle_rad == 0.0 and est.confidence == 0.0


def test_half_the_pad_saturated_gives_the_long_axis():
    """Contact over the whole left half (10 x 20 mm, saturated): the principal axis is the pad's y axis."""
    x, _ = _pad_xy()
    img = np.broadcast_to(np.where(x < 0, SATURATION_MM, 0.0), (SIZE_PX, SIZE_PX)).astype(np.float32)
    est = _estimate(img)
    assert est.defined and est.angle_rad == pytest.approx(math.pi / 2, abs=1e-9)
    assert est.centroid_mm[0] == pytest.approx(-5.0, abs=0.1)


def test_nan_pixels_inside_a_saturated_bar_do_not_change_the_angle_much():
    img = np.minimum(bar(math.radians(35.0), depth_mm=3.0), SATURATION_MM).astype(np.float32)
    holes = img.copy()
    holes[np.random.default_rng(0).random(img.shape) < 0.02] = np.nan  # 2 % dead camera pixels
    est = _estimate(holes)
    assert est.defined and _axial_error_deg(est.angle_rad, math.radians(35.0)) < 1.0


@pytest.mark.parametrize("shape", [(200,), (4, 50, 50), ()])
def test_an_image_that_is_not_2d_is_a_named_error(shape):
    with pytest.raises(ValueError, match=r"depth_mm: expected an \(H, W\) image, got shape"):
        angle_from_image(np.ones(shape), pixel_mm=PIXEL_MM)


@pytest.mark.parametrize("pixel_mm", [0.0, -0.1, math.nan, math.inf])
def test_a_bad_pixel_size_is_a_named_error_not_a_nan_centroid(pixel_mm):
    with pytest.raises(ValueError, match="pixel_mm"):
        angle_from_image(bar(0.3), pixel_mm=pixel_mm)


# ---------------------------------------------------------------- contact at the border


@pytest.mark.parametrize("angle_deg", np.arange(-89.0, 91.0, 7.0).tolist())
@pytest.mark.parametrize("end", [1.0, -1.0])
def test_a_bar_running_off_the_image_edge_keeps_its_angle(angle_deg, end):
    """A 12 mm bar centred 8 mm from the pad centre along its own axis: 2 mm or more of it lies beyond the
    border, which cuts it obliquely. Expected: the angle within BORDER_TOLERANCE_DEG."""
    a = math.radians(angle_deg)
    centre = (end * 8.0 * math.cos(a), end * 8.0 * math.sin(a))
    img = bar(a, length_mm=12.0, centre_mm=centre).astype(np.float32)
    assert img[[0, -1], :].any() or img[:, [0, -1]].any()  # it does touch the border
    est = _estimate(img)
    assert est.defined and _axial_error_deg(est.angle_rad, a) < BORDER_TOLERANCE_DEG


@pytest.mark.parametrize("angle_deg", [0.0, 30.0, -45.0, 90.0])
def test_a_bar_crossing_the_whole_pad_keeps_its_angle(angle_deg):
    est = _estimate(bar(math.radians(angle_deg), length_mm=40.0).astype(np.float32))
    assert est.defined and est.confidence > 0.99
    assert _axial_error_deg(est.angle_rad, math.radians(angle_deg)) < BORDER_TOLERANCE_DEG


# ---------------------------------------------------------------- the +-90 degree wrap


@pytest.mark.parametrize("angle_deg", [90.0, -90.0, 89.9, -89.9, 90.1, -90.1, 89.99, -89.99])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_rods_at_the_wrap_stay_in_range_and_axially_close(angle_deg, dtype):
    est = _estimate(bar(math.radians(angle_deg), length_mm=30.0).astype(dtype))
    assert est.defined and -math.pi / 2 < est.angle_rad <= math.pi / 2
    assert _axial_error_deg(est.angle_rad, math.radians(angle_deg)) < WRAP_TOLERANCE_DEG


@pytest.mark.parametrize("angle_deg", [90.0, -90.0])
def test_exactly_vertical_rods_report_plus_half_pi_in_both_precisions(angle_deg):
    for dtype in (np.float32, np.float64):
        est = _estimate(bar(math.radians(angle_deg), length_mm=30.0).astype(dtype))
        assert est.angle_rad == pytest.approx(math.pi / 2, abs=1e-9)  # never -pi/2


# ---------------------------------------------------------------- float32 against float64


HARD_IMAGES = {
    "bar at 20 deg": lambda: bar(math.radians(20.0)),
    "bar at 89.9 deg": lambda: bar(math.radians(89.9), length_mm=30.0),
    "bar at -90.1 deg": lambda: bar(math.radians(-90.1), length_mm=30.0),
    "bar off the edge": lambda: bar(math.radians(40.0), length_mm=12.0, centre_mm=(6.1, 5.1)),
    "saturated bar": lambda: np.minimum(bar(math.radians(-70.0), depth_mm=3.0), SATURATION_MM),
    "shallow bar near the threshold": lambda: bar(math.radians(10.0), depth_mm=0.12),
    "denormal background": lambda: bar(math.radians(55.0)) + 1e-40,
}


@pytest.mark.parametrize("case", list(HARD_IMAGES))
def test_pose_of_float32_and_float64_images_agree(case):
    """Tolerance: F32_ANGLE_TOL_RAD on the angle, F32_CONFIDENCE_TOL on the confidence, same flag."""
    img = HARD_IMAGES[case]()
    e64, e32 = _estimate(img), _estimate(img.astype(np.float32))
    assert e64.defined and e32.defined
    assert _axial_error_deg(e32.angle_rad, e64.angle_rad) < math.degrees(F32_ANGLE_TOL_RAD)
    assert e32.confidence == pytest.approx(e64.confidence, abs=F32_CONFIDENCE_TOL)


# ---------------------------------------------------------------- metrics


def _pairs() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(0)
    truth = np.minimum(bar(0.4, depth_mm=2.5), SATURATION_MM)
    return {
        "noisy bar": (np.clip(truth + rng.normal(0, 0.05, truth.shape), 0, None), truth),
        "saturated against empty": (np.full(truth.shape, SATURATION_MM), np.zeros(truth.shape)),
        "empty against a bar": (np.zeros(truth.shape), truth),
        "shifted bar": (np.roll(truth, 7, axis=1), truth),
        "denormal against empty": (np.full(truth.shape, 1e-40), np.zeros(truth.shape)),
    }


@pytest.mark.parametrize("case", list(_pairs()))
def test_metrics_of_float32_and_float64_images_agree(case):
    """float64 images against their float32 rounding. Tolerance: 1e-4 dB PSNR, 1e-5 SSIM (both finite)."""
    pred, truth = _pairs()[case]
    p64, s64 = psnr(pred, truth), ssim(pred, truth)
    p32, s32 = psnr(pred.astype(np.float32), truth.astype(np.float32)), ssim(pred.astype(np.float32),
                                                                             truth.astype(np.float32))
    assert np.isfinite([p64, s64, p32, s32]).all()
    assert p32 == pytest.approx(p64, abs=1e-4) and s32 == pytest.approx(s64, abs=1e-5)
    assert -1.0 <= s32 <= 1.0


def test_metrics_of_identical_empty_or_saturated_images_are_the_perfect_scores():
    for value in (0.0, SATURATION_MM):
        img = np.full((SIZE_PX, SIZE_PX), value, np.float32)
        assert psnr(img, img) == np.inf and ssim(img, img) == 1.0


def test_metrics_of_a_saturated_prediction_against_an_empty_truth_are_the_closed_form():
    pred, truth = np.full((SIZE_PX, SIZE_PX), SATURATION_MM, np.float32), np.zeros((SIZE_PX, SIZE_PX), np.float32)
    assert psnr(pred, truth) == pytest.approx(10 * math.log10(DEPTH_RANGE_MM**2 / SATURATION_MM**2), abs=1e-5)
    # SSIM of two constants: the luminance term (2 mu_p mu_t + c1) / (mu_p^2 + mu_t^2 + c1) with mu_t = 0
    c1 = (0.01 * DEPTH_RANGE_MM) ** 2
    assert ssim(pred, truth) == pytest.approx(c1 / (SATURATION_MM**2 + c1), rel=1e-4)


def test_metrics_at_the_float32_maximum_are_finite():
    big = np.full((40, 40), np.finfo(np.float32).max, np.float32)
    zero = np.zeros((40, 40), np.float32)
    p, s = psnr(big, zero), ssim(big, zero)
    assert np.isfinite(p) and p < -700 and np.isfinite(s) and 0.0 <= s < 1e-60


@pytest.mark.parametrize("value", [1e51, 1e200, -1e300])
def test_metrics_refuse_magnitudes_where_ssim_would_overflow_to_nan(value):
    img, zero = np.full((40, 40), value), np.zeros((40, 40))
    for metric in (psnr, ssim):
        with pytest.raises(ValueError, match=re.escape(f"beyond +-{MAX_ABS_MM:g} mm")):
            metric(img, zero)
        with pytest.raises(ValueError, match="beyond"):
            metric(zero, img)
