"""Discrete magnets in closed form: the axially polarised cylinder and a cuboid at any pose (magpylib as oracle)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.spatial.transform import Rotation

from tactile_manip.sim.magnets import cel, cylinder_field_t, magnet_field_t

magpy = pytest.importorskip("magpylib", reason="magpylib is the independent oracle (pip install .[dev])")

DISC_MM = (9.525, 3.175)  # the eFlesh disc: 3/8 x 1/8 in


def _oracle_t(points_mm, *, shape, size_mm, polarisation_t, centre_mm=(0, 0, 0), rotation=None):
    cls = magpy.magnet.Cylinder if shape == "cylinder" else magpy.magnet.Cuboid
    orientation = None if rotation is None else Rotation.from_matrix(rotation)
    # magpylib in SI: metres and tesla
    magnet = cls(polarization=polarisation_t, dimension=np.asarray(size_mm) * 1e-3,
                 position=np.asarray(centre_mm) * 1e-3, orientation=orientation)
    return magnet.getB(np.asarray(points_mm) * 1e-3)


def test_cel_is_the_integral_it_names():
    rng = np.random.default_rng(0)
    for kc, p, c, s in rng.uniform([0.01, 0.0, -2, -2], [1.0, 3.0, 2, 2], (20, 4)):
        integrand = (lambda t: (c * np.cos(t) ** 2 + s * np.sin(t) ** 2)
                     / ((np.cos(t) ** 2 + p * np.sin(t) ** 2) * np.sqrt(np.cos(t) ** 2 + kc**2 * np.sin(t) ** 2)))
        if p == 0:
            continue
        assert cel(kc, p, c, s) == pytest.approx(quad(integrand, 0, np.pi / 2, limit=200)[0], rel=1e-9)


def test_cylinder_matches_the_oracle_outside_inside_and_on_its_axis():
    rng = np.random.default_rng(0)
    points = np.vstack([rng.uniform(-12, 12, (500, 3)), rng.uniform(-1.5, 1.5, (50, 3)),   # around and inside
                        [[0, 0, 5.0], [0, 0, -5.0], [4.7625, 0, 0.3], [3.0, 0, 1.5875]]])  # axis, mantle, face
    field = cylinder_field_t(points, diameter_mm=DISC_MM[0], height_mm=DISC_MM[1], polarisation_t=1.45)
    oracle = _oracle_t(points, shape="cylinder", size_mm=DISC_MM, polarisation_t=(0, 0, 1.45))
    np.testing.assert_allclose(field, oracle, atol=1e-12 + 1e-10 * np.abs(oracle).max())


@pytest.mark.parametrize("shape, size, polarisation", [
    ("cylinder", DISC_MM, (0.0, 0.0, -1.3)),
    ("cuboid", (3.0, 4.0, 5.0), (0.2, -0.1, 1.2)),
])
def test_a_moved_and_turned_magnet_matches_the_oracle(shape, size, polarisation):
    rng = np.random.default_rng(1)
    points = rng.uniform(-15, 15, (400, 3))
    rotation = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    kwargs = dict(shape=shape, size_mm=size, polarisation_t=polarisation, centre_mm=(1.0, 2.0, -3.0),
                  rotation=rotation)
    np.testing.assert_allclose(magnet_field_t(points, **kwargs), _oracle_t(points, **kwargs), atol=1e-12)


def test_float32_points_and_refusals():
    points = np.array([[1.0, 2.0, 4.0]], np.float32)
    field = cylinder_field_t(points, diameter_mm=5.0, height_mm=2.0, polarisation_t=1.0)
    assert field.dtype == np.float64 and np.isfinite(field).all()
    with pytest.raises(ValueError, match="along its axis"):
        magnet_field_t(points, shape="cylinder", size_mm=(5, 2), polarisation_t=(1.0, 0, 1.0))
    with pytest.raises(ValueError, match="'cylinder' or 'cuboid'"):
        magnet_field_t(points, shape="sphere", size_mm=(5,), polarisation_t=(0, 0, 1.0))
    with pytest.raises(ValueError, match="diameter_mm"):
        cylinder_field_t(points, diameter_mm=0.0, height_mm=2.0, polarisation_t=1.0)
    rim = cylinder_field_t(np.array([[2.5, 0.0, 1.0]]), diameter_mm=5.0, height_mm=2.0, polarisation_t=1.0)
    assert np.isfinite(rim).all()                       # the rim's field diverges; the value stays finite
