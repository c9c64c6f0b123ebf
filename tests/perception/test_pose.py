"""Contact angle from a depth image: synthetic bars at known angles, invariants and degenerate images."""

from __future__ import annotations

import math

import numpy as np
import pytest
from checks import assert_sane_estimate
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tactile_manip.perception.pose import MIN_CONTACT_PX, PoseParams, angle_from_image, remove_outliers, wrap_axial

PIXEL_MM = 0.1
SIZE_PX = 100  # a 10 mm x 10 mm pad
ONE_DEG = math.radians(1.0)


def _pad_xy(size: int = SIZE_PX, pixel_mm: float = PIXEL_MM) -> tuple[np.ndarray, np.ndarray]:
    """Pixel centres in the pad frame (mm): column 0 at -x, row 0 at +y, as the estimator assumes."""
    c = (np.arange(size) - (size - 1) / 2) * pixel_mm
    return c[None, :], -c[:, None]


def bar(angle_rad: float, *, length_mm: float = 6.0, width_mm: float = 1.0, depth_mm: float = 1.0,
        centre_mm: tuple[float, float] = (0.0, 0.0), edge_mm: float = 0.2) -> np.ndarray:
    """(100, 100) depth image of a flat-bottomed bar rotated by ``angle_rad`` (CCW from +x), soft edges."""
    x, y = _pad_xy()
    dx, dy = x - centre_mm[0], y - centre_mm[1]
    along = dx * math.cos(angle_rad) + dy * math.sin(angle_rad)
    across = -dx * math.sin(angle_rad) + dy * math.cos(angle_rad)
    ramp = lambda half, u: np.clip((half - np.abs(u)) / edge_mm + 0.5, 0.0, 1.0)  # noqa: E731
    return depth_mm * ramp(length_mm / 2, along) * ramp(width_mm / 2, across)


def ellipse(a_mm: float, b_mm: float, angle_rad: float = 0.0, depth_mm: float = 1.0) -> np.ndarray:
    """(100, 100) depth image of a spherical-cap-like elliptic contact with semi-axes a (along angle), b."""
    x, y = _pad_xy()
    along = x * math.cos(angle_rad) + y * math.sin(angle_rad)
    across = -x * math.sin(angle_rad) + y * math.cos(angle_rad)
    return depth_mm * np.clip(1.0 - (along / a_mm) ** 2 - (across / b_mm) ** 2, 0.0, None)


def axial_error(a: float, b: float) -> float:
    """|a - b| modulo pi, in [0, pi/2]."""
    return abs(wrap_axial(a - b))


# ---------------------------------------------------------------- wrap_axial


def test_wrap_axial_puts_both_ends_at_plus_half_pi() -> None:
    assert wrap_axial(math.pi / 2) == math.pi / 2
    assert wrap_axial(-math.pi / 2) == math.pi / 2
    assert wrap_axial(0.0) == 0.0
    np.testing.assert_array_equal(wrap_axial(np.array([-math.pi / 2, math.pi / 2])), [math.pi / 2, math.pi / 2])


def test_wrap_axial_range_and_period() -> None:
    angles = np.random.default_rng(0).uniform(-20.0, 20.0, 1000)
    wrapped = wrap_axial(angles)
    assert isinstance(wrapped, np.ndarray) and wrapped.shape == angles.shape
    assert np.all((wrapped > -math.pi / 2) & (wrapped <= math.pi / 2))
    turns = (angles - wrapped) / math.pi
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-9)
    assert isinstance(wrap_axial(0.3), float)


def test_wrap_axial_of_a_float_is_the_array_path_bit_for_bit() -> None:
    # floats take a path without numpy; it must agree exactly, at the ends of the range too
    ends = [math.pi / 2, -math.pi / 2, 0.0, -0.0, math.pi, -math.pi, 1.5 * math.pi, math.pi / 2 + 1e-16, 1e-300, 1e10]
    angles = np.concatenate([np.random.default_rng(1).uniform(-50.0, 50.0, 5000), ends])
    np.testing.assert_array_equal([wrap_axial(float(a)) for a in angles], wrap_axial(angles))
    assert math.isnan(wrap_axial(math.nan))


# ---------------------------------------------------------------- known angles


@pytest.mark.parametrize("angle_deg", np.linspace(-87.5, 90.0, 72).round(2).tolist())
def test_bar_angle_is_recovered_within_one_degree(angle_deg: float) -> None:
    est = angle_from_image(bar(math.radians(angle_deg)), pixel_mm=PIXEL_MM)
    assert est.defined and est.reason == ""
    assert -math.pi / 2 < est.angle_rad <= math.pi / 2
    assert axial_error(est.angle_rad, math.radians(angle_deg)) < ONE_DEG


def test_off_centre_bar_angle_and_centroid() -> None:
    est = angle_from_image(bar(math.radians(30.0), centre_mm=(1.5, -2.0), length_mm=4.0), pixel_mm=PIXEL_MM)
    assert est.defined
    assert axial_error(est.angle_rad, math.radians(30.0)) < ONE_DEG
    np.testing.assert_allclose(est.centroid_mm, (1.5, -2.0), atol=0.05)
    assert est.area_mm2 > 4.0  # 4 mm x 1 mm, grown by the Gaussian filter


@pytest.mark.parametrize("angle_deg", [90.0, -90.0, 89.9, 90.1, -89.9, 89.5, -89.5])
def test_angles_at_the_wrap_are_estimated_consistently(angle_deg: float) -> None:
    est = angle_from_image(bar(math.radians(angle_deg)), pixel_mm=PIXEL_MM)
    assert est.defined
    assert -math.pi / 2 < est.angle_rad <= math.pi / 2  # never -pi/2
    assert axial_error(est.angle_rad, math.radians(angle_deg)) < ONE_DEG


def test_vertical_bar_reports_plus_half_pi() -> None:
    # The image of a vertical bar is exactly symmetric: the estimate is exactly on the wrap and must be +pi/2.
    x, _ = _pad_xy()
    img = np.broadcast_to(np.where(np.abs(x) < 0.5, 1.0, 0.0), (SIZE_PX, SIZE_PX)).copy()
    img[:20] = img[-20:] = 0.0
    est = angle_from_image(img, pixel_mm=PIXEL_MM)
    assert est.defined
    assert est.angle_rad == pytest.approx(math.pi / 2, abs=1e-9)


def test_rotating_the_image_by_90_degrees_rotates_the_estimate() -> None:
    for angle_deg in (-70.0, -20.0, 0.0, 15.0, 44.0, 80.0):
        img = bar(math.radians(angle_deg), centre_mm=(0.7, -0.4))
        base = angle_from_image(img, pixel_mm=PIXEL_MM)
        for k in (1, 2, 3):
            turned = angle_from_image(np.rot90(img, k), pixel_mm=PIXEL_MM)
            assert turned.defined
            assert axial_error(turned.angle_rad, base.angle_rad + k * math.pi / 2) < 1e-6
            assert turned.confidence == pytest.approx(base.confidence, abs=1e-9)


# ---------------------------------------------------------------- undefined angles


def test_isotropic_disc_is_undefined() -> None:
    est = angle_from_image(ellipse(2.0, 2.0), pixel_mm=PIXEL_MM)
    assert not est.defined
    assert "isotropic" in est.reason
    assert est.angle_rad == 0.0 and est.confidence == 0.0
    assert est.area_mm2 > 10.0  # the disc is a real contact, only its angle is undefined


def test_empty_image_is_undefined() -> None:
    est = angle_from_image(np.zeros((SIZE_PX, SIZE_PX)), pixel_mm=PIXEL_MM)
    assert not est.defined and "empty" in est.reason
    assert est.area_mm2 == 0.0 and not math.isnan(est.angle_rad)
    shallow = angle_from_image(np.full((SIZE_PX, SIZE_PX), 0.05), pixel_mm=PIXEL_MM)  # below the threshold
    assert not shallow.defined and "empty" in shallow.reason


def test_tiny_contact_is_too_small() -> None:
    img = np.zeros((SIZE_PX, SIZE_PX))
    img[50:52, 40:44] = 1.0  # 2x4 px: after the filter, 16 px deeper than the threshold (< MIN_CONTACT_PX)
    est = angle_from_image(img, pixel_mm=PIXEL_MM)
    assert not est.defined
    assert "too small" in est.reason and f"< {MIN_CONTACT_PX}" in est.reason


def test_single_pixel_contact_is_too_small_not_empty() -> None:
    img = np.zeros((SIZE_PX, SIZE_PX))
    img[50, 50] = 1.0
    est = angle_from_image(img, pixel_mm=PIXEL_MM)
    assert not est.defined
    assert "too small" in est.reason


def test_single_pixel_contact_is_undefined() -> None:
    img = np.zeros((SIZE_PX, SIZE_PX))
    img[50, 50] = 1.0
    est = angle_from_image(img, pixel_mm=PIXEL_MM)
    assert not est.defined and est.reason
    assert est.confidence == 0.0


# ---------------------------------------------------------------- robustness


def test_nan_and_inf_pixels_are_no_contact() -> None:
    img = bar(math.radians(25.0))
    clean = angle_from_image(img, pixel_mm=PIXEL_MM)
    broken = img.copy()
    broken[5, 5], broken[90, 10], broken[10, 90] = np.nan, np.inf, -np.inf
    est = angle_from_image(broken, pixel_mm=PIXEL_MM)
    assert est.defined and np.isfinite([est.angle_rad, est.confidence, est.area_mm2, *est.centroid_mm]).all()
    assert est.angle_rad == pytest.approx(clean.angle_rad, abs=1e-9)
    inside = img.copy()
    inside[50, 50] = np.nan  # a hole inside the contact: a small, finite change
    assert axial_error(angle_from_image(inside, pixel_mm=PIXEL_MM).angle_rad, math.radians(25.0)) < ONE_DEG
    for fill in (np.nan, np.inf, -np.inf):
        est = angle_from_image(np.full((SIZE_PX, SIZE_PX), fill), pixel_mm=PIXEL_MM)
        assert not est.defined and "empty" in est.reason


def test_saturated_bar_still_gives_the_angle() -> None:
    for angle_deg in (-60.0, 10.0, 75.0):
        img = np.minimum(bar(math.radians(angle_deg), depth_mm=3.0), 1.9)  # VBTS clips near 1.92 mm
        est = angle_from_image(img, pixel_mm=PIXEL_MM)
        assert est.defined and axial_error(est.angle_rad, math.radians(angle_deg)) < ONE_DEG


def test_float32_and_float64_images_agree() -> None:
    img = bar(math.radians(-33.0)) + ellipse(1.0, 0.5, 0.4, 0.3)
    e64 = angle_from_image(img, pixel_mm=PIXEL_MM)
    e32 = angle_from_image(img.astype(np.float32), pixel_mm=PIXEL_MM)
    assert e32.defined == e64.defined
    assert e32.angle_rad == pytest.approx(e64.angle_rad, abs=1e-5)
    assert e32.confidence == pytest.approx(e64.confidence, abs=1e-5)


def test_confidence_is_higher_for_a_thin_bar_than_a_fat_ellipse() -> None:
    thin = angle_from_image(bar(0.3, width_mm=0.6), pixel_mm=PIXEL_MM)
    fat = angle_from_image(ellipse(2.5, 1.8, 0.3), pixel_mm=PIXEL_MM)
    assert thin.defined and fat.defined
    assert axial_error(fat.angle_rad, 0.3) < ONE_DEG
    assert 0.0 <= fat.confidence < thin.confidence <= 1.0
    assert thin.confidence > 0.8


def _bar_with_speckle() -> tuple[np.ndarray, np.ndarray]:
    img = bar(math.radians(40.0))
    speckled = img.copy()
    speckled[3:5, 90:92] = 1.5  # a 2x2 px ghost far from the bar
    return img, speckled


def test_remove_outliers_drops_a_far_speckle_and_keeps_the_contact() -> None:
    img, speckled = _bar_with_speckle()
    cleaned = remove_outliers(speckled)
    np.testing.assert_array_equal(cleaned[3:5, 90:92], 0.0)
    contact = img > 0.1
    np.testing.assert_array_equal(cleaned[contact], img[contact])
    # so the speckle hardly moves the estimate (it would pull the principal axis towards the corner)
    with_speckle = angle_from_image(speckled, pixel_mm=PIXEL_MM)
    assert with_speckle.defined
    assert axial_error(with_speckle.angle_rad, math.radians(40.0)) < ONE_DEG
    assert axial_error(with_speckle.angle_rad, angle_from_image(img, pixel_mm=PIXEL_MM).angle_rad) < 1e-3


def test_remove_outliers_only_touches_the_small_regions() -> None:
    img, speckled = _bar_with_speckle()
    np.testing.assert_array_equal(remove_outliers(speckled), img)


def test_remove_outliers_keeps_comparable_regions_and_clips_negative_depth() -> None:
    img = bar(0.0, centre_mm=(0.0, 2.5), length_mm=5.0) + bar(0.0, centre_mm=(0.0, -2.5), length_mm=4.0)
    img[0, 0] = -0.5
    cleaned = remove_outliers(img)
    assert cleaned.min() == 0.0
    contact = img > 0.1
    np.testing.assert_array_equal(cleaned[contact], img[contact])
    single = bar(0.0)
    single[0, 0] = -0.5
    np.testing.assert_array_equal(remove_outliers(single), np.clip(single, 0.0, None))


def test_never_nan_on_200_random_images() -> None:
    rng = np.random.default_rng(0)
    checker = (np.indices((40, 40)).sum(axis=0) % 2).astype(np.float64)
    images = [np.zeros((40, 40)), np.ones((40, 40)), np.full((40, 40), 0.1), checker, 1.9 * checker,
              np.full((40, 40), 1e300), np.full((40, 40), np.finfo(np.float32).max, np.float32)]
    while len(images) < 200:
        kind = len(images) % 5
        shape = tuple(rng.integers(1, 60, 2))
        if kind == 0:
            img = rng.uniform(0, 2, shape)
        elif kind == 1:
            img = rng.normal(0, 1, shape)
        elif kind == 2:
            img = np.where(rng.random(shape) < 0.05, rng.uniform(0, 2, shape), 0.0)
        elif kind == 3:
            img = rng.uniform(0, 2, shape) * (rng.random(shape) < 0.5) * 10.0 ** rng.integers(-3, 6)
        else:
            img = rng.uniform(0, 2, shape)
            img[rng.random(shape) < 0.1] = rng.choice([np.nan, np.inf, -np.inf])
        images.append(img)
    for img in images:
        assert_sane_estimate(angle_from_image(img, pixel_mm=PIXEL_MM))


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("value", [1.7e308, 1e308])
def test_never_nan_for_depths_near_the_float_maximum(value: float) -> None:
    img = np.zeros((40, 40))
    img[10:30, 18:22] = value
    assert_sane_estimate(angle_from_image(img, pixel_mm=PIXEL_MM))


@settings(max_examples=60, deadline=None)
@given(hnp.arrays(np.float64, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=24),
                  elements=st.floats(allow_nan=True, allow_infinity=True, width=64)))
def test_never_nan_for_arbitrary_images(img: np.ndarray) -> None:
    assert_sane_estimate(angle_from_image(img, pixel_mm=PIXEL_MM))


def test_a_positive_background_level_is_removed_before_the_pca():
    img = bar(math.radians(25.0))
    lifted = img + 0.137                                  # the interpolation baselines' fitted offset, mm
    kept = angle_from_image(lifted, pixel_mm=PIXEL_MM, params=PoseParams(background="none"))
    removed = angle_from_image(lifted, pixel_mm=PIXEL_MM)
    assert kept.area_mm2 > 0.9 * (SIZE_PX * PIXEL_MM) ** 2            # the whole pad counts as contact
    assert removed.defined and axial_error(removed.angle_rad, math.radians(25.0)) < ONE_DEG
    assert removed.area_mm2 < 15.0 and removed.confidence > kept.confidence + 0.3   # the 6 x 1 mm bar, blurred
    same = angle_from_image(img, pixel_mm=PIXEL_MM)                   # zero background: unchanged
    assert same.angle_rad == angle_from_image(img, pixel_mm=PIXEL_MM, params=PoseParams(background="none")).angle_rad
    with pytest.raises(ValueError, match="background"):
        PoseParams(background="mean")
