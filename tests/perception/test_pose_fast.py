"""The cropped float32 pose pipeline against the full-image float64 reference it replaces.

``angle_from_image`` (on its C kernel and on its numpy path) must give what ``reference_angle_from_image`` (the
pipeline as first written, kept in tactile_manip/evaluation/pose_reference.py) gives: the same defined flag and
reason, and angle, confidence, centroid and area within float32 rounding. Images: simulated VBTS presses of
the rods and the SuperMag objects, synthetic bars and blobs with speckle, hard cases (empty, isotropic, tiny,
+-90 deg, NaN, huge values, a positive background, contact at the border), in float32 and float64, and other
PoseParams.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_manip.perception.pose import PoseParams, _median, angle_from_image, wrap_axial
from tactile_manip.evaluation.pose_reference import reference_angle_from_image
from tactile_manip.types import AngleEstimate

pytestmark = pytest.mark.usefixtures("pose_path")  # every test on both paths of the pose stage

PIXEL_MM = 0.1
SIZE_PX = 200
ANGLE_TOL_DEG = 1e-3      # float32 against float64 (measured on the test split's reconstructions: 2e-6 deg)
CONFIDENCE_TOL = 1e-5
CENTROID_TOL_MM = 1e-5
AREA_TOL_MM2 = 0.05       # five pixels whose filtered depth sits within float32 rounding of the threshold


def _pad_xy() -> tuple[np.ndarray, np.ndarray]:
    c = (np.arange(SIZE_PX) - (SIZE_PX - 1) / 2) * PIXEL_MM
    return c[None, :], -c[:, None]


def bar(angle_rad: float, *, length_mm: float = 6.0, width_mm: float = 1.0, depth_mm: float = 1.0,
        centre_mm: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """(200, 200) float64 image of a flat-bottomed bar at ``angle_rad`` (CCW from +x), 0.2 mm soft edges."""
    x, y = _pad_xy()
    dx, dy = x - centre_mm[0], y - centre_mm[1]
    along = dx * math.cos(angle_rad) + dy * math.sin(angle_rad)
    across = -dx * math.sin(angle_rad) + dy * math.cos(angle_rad)
    ramp = lambda half, u: np.clip((half - np.abs(u)) / 0.2 + 0.5, 0.0, 1.0)  # noqa: E731
    return depth_mm * ramp(length_mm / 2, along) * ramp(width_mm / 2, across)


def blob(a_mm: float, b_mm: float, angle_rad: float, centre_mm: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    x, y = _pad_xy()
    dx, dy = x - centre_mm[0], y - centre_mm[1]
    along = dx * math.cos(angle_rad) + dy * math.sin(angle_rad)
    across = -dx * math.sin(angle_rad) + dy * math.cos(angle_rad)
    return np.clip(1.0 - (along / a_mm) ** 2 - (across / b_mm) ** 2, 0.0, None)


def assert_same(img: np.ndarray, params: PoseParams | None = None, pixel_mm: float = PIXEL_MM) -> AngleEstimate:
    new = angle_from_image(img, pixel_mm=pixel_mm, params=params)
    ref = reference_angle_from_image(img, pixel_mm=pixel_mm, params=params)
    assert new.defined == ref.defined, (new, ref)
    assert new.reason.split(" (")[0] == ref.reason.split(" (")[0], (new, ref)
    assert abs(math.degrees(wrap_axial(new.angle_rad - ref.angle_rad))) < ANGLE_TOL_DEG, (new, ref)
    assert -math.pi / 2 < new.angle_rad <= math.pi / 2
    assert new.confidence == pytest.approx(ref.confidence, abs=CONFIDENCE_TOL)
    np.testing.assert_allclose(new.centroid_mm, ref.centroid_mm, atol=CENTROID_TOL_MM)
    assert new.area_mm2 == pytest.approx(ref.area_mm2, abs=AREA_TOL_MM2)
    return new


@pytest.fixture(scope="module")
def simulated_presses() -> list[np.ndarray]:
    """VBTS depth images (200, 200) float32 of 24 simulated presses: the six rods and the SuperMag objects."""
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.sim.shapes import make_indenter

    pair, rng = SensorPair(seed=0), np.random.default_rng(0)
    specs = [("cylinder", 3.0), ("hex_bar", 4.0), ("square_bar", 2.5), ("cylinder", 6.0), ("allen_key", None),
             ("letter_r", None)]
    images = []
    for i in range(24):
        kind, size = specs[i % len(specs)]
        indenter = make_indenter(kind, size_mm=size) if size else make_indenter(kind)
        pose = IndenterPose(*rng.uniform(-3.0, 3.0, size=2), yaw_rad=float(rng.uniform(-math.pi, math.pi)))
        images.append(pair.press(indenter, pose, rng.uniform(8.0, 11.0), rng).depth_mm)
    return images


def test_simulated_presses_match_the_reference(simulated_presses) -> None:
    defined = [assert_same(img).defined for img in simulated_presses]
    assert sum(defined) >= 20  # the comparison covers real angles, not only undefined contacts


def test_speckle_far_and_near_the_contact_is_removed_as_the_reference_removes_it() -> None:
    rng = np.random.default_rng(0)
    for k in range(12):
        img = bar(rng.uniform(-math.pi / 2, math.pi / 2), centre_mm=tuple(rng.uniform(-4, 4, 2)))
        for _ in range(rng.integers(1, 6)):  # ghosts of 1-6 px, some inside the filter's reach of the bar
            r, c = rng.integers(0, SIZE_PX - 3, 2)
            img[r:r + rng.integers(1, 3), c:c + rng.integers(1, 4)] = rng.uniform(0.2, 1.5)
        assert_same(img.astype(np.float32) if k % 2 else img)


def test_two_comparable_contacts_both_count() -> None:
    img = bar(0.4, centre_mm=(-5.0, 3.0)) + 0.8 * bar(-0.9, centre_mm=(5.0, -4.0))
    assert assert_same(img).defined


def test_a_positive_background_level_is_removed_first() -> None:
    img = bar(math.radians(30.0)) + 0.14  # the interpolation baselines' offset
    assert assert_same(img).defined
    faint = np.where(blob(6.0, 5.0, 0.2) > 0, 0.02, 0.0) + np.maximum(bar(1.0, length_mm=9.0), 0.0)
    assert assert_same(faint.astype(np.float32)).defined  # more than half the pixels faintly positive
    assert_same(np.full((SIZE_PX, SIZE_PX), 0.5) + 1e-3 * np.random.default_rng(0).random((SIZE_PX, SIZE_PX)))


@pytest.mark.parametrize("angle_deg", [90.0, -90.0, 89.99, -89.99, 90.01, 45.0, 0.0])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_angles_at_the_wrap(angle_deg, dtype) -> None:
    est = assert_same(bar(math.radians(angle_deg), length_mm=30.0).astype(dtype))
    assert abs(math.degrees(wrap_axial(est.angle_rad - math.radians(angle_deg)))) < 0.05


HARD = {
    "empty": lambda: np.zeros((SIZE_PX, SIZE_PX)),
    "below threshold": lambda: np.full((SIZE_PX, SIZE_PX), 0.05),
    "negative": lambda: -bar(0.3),
    "one pixel": lambda: np.pad(np.ones((1, 1)) * 1.9, ((100, 99), (7, 192))),
    "tiny contact": lambda: blob(0.35, 0.25, 0.5, (9.7, -9.7)),
    "isotropic disc": lambda: blob(3.0, 3.0, 0.0),
    "nearly isotropic": lambda: blob(3.0, 2.9, 0.7),
    "uniform": lambda: np.full((SIZE_PX, SIZE_PX), 1.9),
    "float32 maximum": lambda: np.full((SIZE_PX, SIZE_PX), float(np.finfo(np.float32).max)),
    "huge float64 pixel": lambda: np.where(np.arange(SIZE_PX)[:, None] == 100, 1e300, bar(0.2)),
    "NaN and inf pixels": lambda: np.where(np.random.default_rng(0).random((SIZE_PX, SIZE_PX)) < 0.02,
                                           np.nan, bar(0.8) - 1e-9) + np.where(np.eye(SIZE_PX) > 0, np.inf, 0.0),
    "NaN everywhere": lambda: np.full((SIZE_PX, SIZE_PX), np.nan),
    # a faint plateau below the threshold beside the bar: the filter reads it up to twice its radius away
    "sub-threshold plateau": lambda: np.maximum(bar(0.0, length_mm=4.0), np.where(
        (_pad_xy()[1] > 0.7) & (_pad_xy()[1] < 3.0) & (_pad_xy()[0] > 0.0) & (_pad_xy()[0] < 2.5), 0.099, 0.0)),
    "bar through the corner": lambda: bar(math.radians(45.0), length_mm=12.0, centre_mm=(9.0, 9.0)),
    "bar across the pad": lambda: bar(math.radians(-20.0), length_mm=40.0, width_mm=3.0),
    "wide bar across the pad at 60 deg": lambda: bar(math.radians(60.0), length_mm=40.0, width_mm=6.0,
                                                     centre_mm=(1.5, -1.0)),
    "bar ending outside the aperture": lambda: bar(math.radians(-35.0), length_mm=10.0, centre_mm=(6.0, 5.0)),
    "bar only in the corner beyond the aperture": lambda: bar(math.radians(45.0), length_mm=3.0,
                                                              centre_mm=(9.2, -9.2)),
    "half the pad": lambda: np.broadcast_to(np.where(_pad_xy()[0] < 0, 1.9, 0.0), (SIZE_PX, SIZE_PX)),
    "a 1x1 image": lambda: np.ones((1, 1)),
    "no pixels": lambda: np.zeros((0, 0)),
    "a 5x300 image": lambda: np.pad(np.ones((3, 200)), ((1, 1), (50, 50))),
}


@pytest.mark.parametrize("case", list(HARD))
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_hard_images_match_the_reference(case, dtype) -> None:
    with np.errstate(over="ignore", invalid="ignore"):  # casting 1e300 to float32 is the point of one case
        img = np.asarray(HARD[case]()).astype(dtype)
    assert_same(img)


@pytest.mark.parametrize("params", [PoseParams(sigma_mm=0.0), PoseParams(sigma_mm=0.05), PoseParams(sigma_mm=0.8),
                                    PoseParams(sigma_mm=3.0),  # a filter wider than half the image
                                    PoseParams(threshold_mm=0.0), PoseParams(threshold_mm=0.5),
                                    PoseParams(outlier_fraction=0.0), PoseParams(outlier_fraction=1.0),
                                    PoseParams(background="none"), PoseParams(min_contact_px=5000),
                                    PoseParams(isotropy_limit=0.2), PoseParams(aperture="none")])
def test_other_parameters_match_the_reference(params) -> None:
    rng = np.random.default_rng(0)
    img = bar(0.7, centre_mm=(2.0, -3.0)) + 0.6 * blob(1.0, 0.6, -0.4, (-6.0, 5.0)) + 0.12
    img[10:12, 180:183] = 1.0
    assert_same(img + 0.01 * rng.random(img.shape), params)
    assert_same(img.astype(np.float32), params, pixel_mm=0.07)


def test_the_median_is_numpys_float64_median() -> None:
    rng = np.random.default_rng(0)
    cases = [rng.random(40_000), np.maximum(rng.standard_normal(40_001), 0.0), rng.integers(0, 3, 5000) * 0.5,
             np.zeros(4096), rng.random(7), np.float32(rng.standard_normal(40_000))]
    for values in cases:
        assert _median(values) == float(np.median(np.asarray(values, np.float64)))
