"""The moments' aperture (``PoseParams.aperture``): a rod wider than the pad keeps its own axis.

On the 20 mm pad a 5-8 mm bar crosses the whole image; the square edges cut it into a sheared band whose
principal axis leans towards the diagonal. The disc aperture cuts any straight band symmetrically.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_manip.perception.pose import PoseParams, angle_from_image, aperture_disc, wrap_axial

pytestmark = pytest.mark.usefixtures("pose_path")  # every test on both paths of the pose stage

PIXEL_MM = 0.1
SIZE_PX = 200  # the 20 mm pad of the shipped model's images
NONE = PoseParams(aperture="none")


def band(angle_deg: float, width_mm: float, centre_mm: tuple[float, float] = (0.0, 0.0),
         length_mm: float = 40.0) -> np.ndarray:
    """(200, 200) float32 image of a flat bar 1 mm deep at ``angle_deg`` (CCW from +x), 0.2 mm soft edges."""
    c = (np.arange(SIZE_PX) - (SIZE_PX - 1) / 2) * PIXEL_MM
    dx, dy = c[None, :] - centre_mm[0], -c[:, None] - centre_mm[1]
    a = math.radians(angle_deg)
    along, across = dx * math.cos(a) + dy * math.sin(a), -dx * math.sin(a) + dy * math.cos(a)
    ramp = lambda half, u: np.clip((half - np.abs(u)) / 0.2 + 0.5, 0.0, 1.0)  # noqa: E731
    return (ramp(length_mm / 2, along) * ramp(width_mm / 2, across)).astype(np.float32)


def error_deg(est, angle_deg: float) -> float:
    return abs(math.degrees(wrap_axial(est.angle_rad - math.radians(angle_deg))))


@pytest.mark.parametrize("angle_deg", [-89.0, -75.0, -60.0, -30.0, 15.0, 30.0, 55.0, 62.0, 89.5])
@pytest.mark.parametrize("width_mm", [2.0, 5.0, 8.0])
@pytest.mark.parametrize("centre_mm", [(0.0, 0.0), (1.5, -2.0), (-3.0, 3.0)])
def test_a_bar_across_the_pad_keeps_its_axis(angle_deg, width_mm, centre_mm) -> None:
    img = band(angle_deg, width_mm, centre_mm)
    disc, whole = angle_from_image(img, pixel_mm=PIXEL_MM), angle_from_image(img, pixel_mm=PIXEL_MM, params=NONE)
    assert disc.defined and whole.defined
    assert error_deg(disc, angle_deg) < 0.01
    assert disc.centroid_mm == pytest.approx(whole.centroid_mm, abs=1e-9)  # over the whole contact, both
    assert disc.area_mm2 == whole.area_mm2


@pytest.mark.parametrize("angle_deg", [30.0, 55.0, 62.0, -60.0])
def test_the_whole_image_moments_lean_towards_the_diagonal(angle_deg) -> None:
    """The bias the aperture removes (the paper's pipeline, aperture "none"), on exact images."""
    est = angle_from_image(band(angle_deg, 5.0), pixel_mm=PIXEL_MM, params=NONE)
    assert error_deg(est, angle_deg) > 1.0
    assert abs(abs(math.degrees(est.angle_rad)) - 45.0) < abs(abs(angle_deg) - 45.0)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_contacts_inside_the_aperture_are_left_alone(dtype) -> None:
    img = band(20.0, 1.0, (2.0, 1.0), length_mm=6.0).astype(dtype)
    assert angle_from_image(img, pixel_mm=PIXEL_MM) == angle_from_image(img, pixel_mm=PIXEL_MM, params=NONE)


def test_a_contact_beyond_the_aperture_keeps_its_whole_image_angle() -> None:
    img = band(-45.0, 1.0, (9.0, 9.0), length_mm=3.0)  # in the corner, outside the disc
    est = angle_from_image(img, pixel_mm=PIXEL_MM)
    assert est == angle_from_image(img, pixel_mm=PIXEL_MM, params=NONE)
    assert est.defined and error_deg(est, -45.0) < 1.0


def test_the_aperture_is_a_centred_disc_off_the_image_border() -> None:
    disc = aperture_disc(SIZE_PX, SIZE_PX, 3.0)
    assert disc.shape == (SIZE_PX, SIZE_PX) and not disc.flags.writeable
    assert disc[100, 100] == 1.0 and disc[0, 100] == 0.0 and disc[100, 0] == 0.0 and disc[0, 0] == 0.0
    np.testing.assert_array_equal(disc, disc[::-1]), np.testing.assert_array_equal(disc, disc.T)
    assert 0.0 < disc[100, 6] < 1.0  # radius 94 px: the anti-aliased edge, 6 px in from the border
    assert math.pi * 94**2 == pytest.approx(disc.sum(), rel=1e-3)


def test_an_unknown_aperture_is_refused() -> None:
    with pytest.raises(ValueError, match="aperture must be 'disc' or 'none'"):
        PoseParams(aperture="square")
