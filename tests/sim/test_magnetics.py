"""Tests of the closed-form cuboid field, the dipole sum and the skin discretisation (magpylib as oracle)."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_manip.boards import load_board
from tactile_manip.sim.chip import chip_positions_mm
from tactile_manip.sim.magnetics import (
    cuboid_field_t,
    dipole_field_t,
    skin_cells,
    skin_dipoles,
)

magpy = pytest.importorskip("magpylib", reason="magpylib is the independent oracle (pip install .[dev])")

SIZE_MM = np.array([20.0, 20.0, 2.5])
CENTRE_MM = np.array([0.0, 0.0, -1.25])  # the skin in the pad frame
UT = 1e-6  # tesla


def _magpylib_t(points_mm: np.ndarray, j_t, size_mm=SIZE_MM, centre_mm=CENTRE_MM) -> np.ndarray:
    magnet = magpy.magnet.Cuboid(polarization=np.asarray(j_t, float), dimension=np.asarray(size_mm) * 1e-3,
                                 position=np.asarray(centre_mm) * 1e-3)
    return magnet.getB(np.asarray(points_mm) * 1e-3)


def _chips(gap_mm: float) -> np.ndarray:
    return chip_positions_mm(load_board("supermag-4x4"), thickness_mm=2.5, gap_mm=gap_mm)


@pytest.mark.parametrize("gap_mm", [0.5, 1.0, 2.0])
@pytest.mark.parametrize("j_t", [(0.0, 0.0, 0.05), (0.04, -0.03, 0.0), (0.02, 0.01, -0.11)])
def test_cuboid_matches_magpylib_at_chips(gap_mm, j_t):
    pts = _chips(gap_mm)
    got = cuboid_field_t(pts, size_mm=SIZE_MM, centre_mm=CENTRE_MM, polarisation_t=j_t)
    np.testing.assert_allclose(got, _magpylib_t(pts, j_t), rtol=0, atol=1 * UT)


def test_cuboid_matches_magpylib_at_random_points():
    rng = np.random.default_rng(0)
    size, centre = np.array([3.0, 7.0, 1.5]), np.array([0.5, -1.0, 2.0])
    pts = rng.uniform(-15.0, 15.0, (3000, 3))
    outside = np.any(np.abs(pts - centre) > size / 2 + 1e-3, axis=1)
    j_t = rng.normal(0.0, 0.1, 3)
    got = cuboid_field_t(pts[outside], size_mm=size, centre_mm=centre, polarisation_t=j_t)
    np.testing.assert_allclose(got, _magpylib_t(pts[outside], j_t, size, centre), rtol=0, atol=1e-3 * UT)


def test_cuboid_inside_adds_polarisation_like_magpylib():
    pts = np.array([[0.0, 0.0, -1.25], [9.0, -9.0, -0.1], [-3.0, 4.0, -2.4]])
    j_t = (0.01, -0.02, 0.05)
    got = cuboid_field_t(pts, size_mm=SIZE_MM, centre_mm=CENTRE_MM, polarisation_t=j_t)
    np.testing.assert_allclose(got, _magpylib_t(pts, j_t), rtol=0, atol=1e-3 * UT)


def test_cuboid_single_point_shape():
    got = cuboid_field_t([0.0, 0.0, -4.0], size_mm=SIZE_MM, centre_mm=CENTRE_MM, polarisation_t=(0, 0, 0.05))
    assert got.shape == (3,)


def test_cuboid_is_finite_on_faces_edges_corners_and_faces_give_outside_limit():
    j_t = (0.01, 0.02, 0.05)
    boundary = np.array([[10.0, 0.0, -1.25], [10.0, 10.0, 0.0], [10.0, 10.0, -1.0], [3.0, 4.0, 0.0],
                         [3.0, 4.0, -2.5], [10.0, -3.0, -2.5], [20.0, 10.0, 0.0]])
    got = cuboid_field_t(boundary, size_mm=SIZE_MM, centre_mm=CENTRE_MM, polarisation_t=j_t)
    assert np.all(np.isfinite(got))
    face = np.array([[3.0, 4.0, 0.0], [3.0, 4.0, -2.5], [10.0, 2.0, -1.0]])
    nudge = np.array([[0, 0, 1e-9], [0, 0, -1e-9], [1e-9, 0, 0]])
    on = cuboid_field_t(face, size_mm=SIZE_MM, centre_mm=CENTRE_MM, polarisation_t=j_t)
    off = cuboid_field_t(face + nudge, size_mm=SIZE_MM, centre_mm=CENTRE_MM, polarisation_t=j_t)
    np.testing.assert_allclose(on, off, rtol=0, atol=1e-3 * UT)


def test_cuboid_far_field_tends_to_dipole():
    j_t = np.array([0.02, -0.01, 0.05])
    moment = j_t * np.prod(SIZE_MM)
    direction = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    errors = []
    for dist in (100.0, 200.0, 400.0):
        pt = CENTRE_MM + dist * direction
        exact = cuboid_field_t(pt, size_mm=SIZE_MM, centre_mm=CENTRE_MM, polarisation_t=j_t)
        dip = dipole_field_t(pt, CENTRE_MM[None], moment[None])
        errors.append(np.linalg.norm(exact - dip) / np.linalg.norm(dip))
    assert errors[2] < 1e-3
    # a centred cuboid has no quadrupole: the error falls like (size / distance)^2
    assert errors[0] / errors[1] > 3.5 and errors[1] / errors[2] > 3.5


def test_cuboid_mirror_symmetry():
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(0.5, 15.0, 50), rng.uniform(-15, 15, 50), rng.uniform(-8, -3, 50)])
    mirrored = pts * np.array([-1.0, 1.0, 1.0])
    kw = dict(size_mm=SIZE_MM, centre_mm=CENTRE_MM, polarisation_t=(0.0, 0.0, 0.05))
    b, bm = cuboid_field_t(pts, **kw), cuboid_field_t(mirrored, **kw)
    np.testing.assert_allclose(bm[:, 2], b[:, 2], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(bm[:, 0], -b[:, 0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(bm[:, 1], b[:, 1], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("gap_mm", [0.5, 1.0])
def test_skin_dipoles_converge_to_cuboid(gap_mm):
    chips = _chips(gap_mm)
    j_t = (0.0, 0.0, 0.05)
    exact = cuboid_field_t(chips, size_mm=SIZE_MM, centre_mm=CENTRE_MM, polarisation_t=j_t)
    errors = []
    for cell_mm, nodes in [(1.0, 2), (0.5, 4), (0.25, 6)]:
        cells = skin_cells(size_mm=20.0, thickness_mm=2.5, cell_mm=cell_mm, nodes=nodes)
        approx = dipole_field_t(chips, *skin_dipoles(cells, j_t))
        errors.append(np.max(np.linalg.norm(approx - exact, axis=1) / np.linalg.norm(exact, axis=1)))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.02


def test_single_dipole_matches_hand_formula():
    m = np.array([0.0, 0.0, 2.0])  # T mm^3
    pts = np.array([[0.0, 0.0, 2.0], [2.0, 0.0, 0.0], [1.0, 2.0, -2.0]])
    got = dipole_field_t(pts + 1.0, np.array([[1.0, 1.0, 1.0]]), m[None])
    np.testing.assert_allclose(got[0], [0, 0, 2 * 2.0 / (4 * np.pi * 8.0)], rtol=1e-14)
    np.testing.assert_allclose(got[1], [0, 0, -2.0 / (4 * np.pi * 8.0)], rtol=1e-14, atol=1e-18)
    r = pts[2]
    rn = np.linalg.norm(r)
    hand = (3 * (m @ r) * r / rn**2 - m) / (4 * np.pi * rn**3)
    np.testing.assert_allclose(got[2], hand, rtol=1e-14)


def test_dipole_sum_in_chunks_matches_brute_force_and_skips_coincident():
    rng = np.random.default_rng(2)
    pts, pos, mom = rng.normal(size=(16, 3)), rng.normal(size=(5000, 3)) * 5, rng.normal(size=(5000, 3))
    pos[7] = pts[3]  # a dipole sitting on a field point contributes nothing
    d = pts[:, None, :] - pos[None]
    r = np.linalg.norm(d, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = (3 * np.sum(d * mom, -1, keepdims=True) * d / r**5 - mom / r**3) / (4 * np.pi)
    terms[3, 7] = 0.0
    np.testing.assert_allclose(dipole_field_t(pts, pos, mom), terms.sum(1), rtol=1e-10)


def test_skin_cells_layout_and_volume():
    cells = skin_cells(size_mm=20.0, thickness_mm=2.5, cell_mm=0.3, nodes=6)
    n = round(20.0 / 0.3)
    assert cells.cell_mm == pytest.approx(20.0 / n)
    assert cells.xy_mm.shape == (n, n, 2) and cells.z_mm.shape == (6,) and cells.volume_mm3.shape == (6,)
    assert cells.xy_mm[0, 0, 1] > 0 > cells.xy_mm[-1, 0, 1]  # row 0 at +y
    assert cells.xy_mm[0, 0, 0] < 0 < cells.xy_mm[0, -1, 0]  # col 0 at -x
    assert np.all((cells.z_mm > -2.5) & (cells.z_mm < 0))
    assert cells.volume_mm3.sum() * n * n == pytest.approx(20.0 * 20.0 * 2.5, rel=1e-12)
    pos, mom = skin_dipoles(cells, (0.0, 0.0, 0.05))
    assert pos.shape == mom.shape == (cells.n_dipoles, 3)
    np.testing.assert_allclose(mom.sum(0), [0.0, 0.0, 0.05 * 1000.0], rtol=1e-12)
    np.testing.assert_allclose(pos.mean(0), [0.0, 0.0, -1.25], atol=1e-12)


@pytest.mark.parametrize("call, name", [
    (lambda: cuboid_field_t(np.zeros((4, 2)), size_mm=SIZE_MM, polarisation_t=(0, 0, 1)), "points_mm"),
    (lambda: cuboid_field_t(np.zeros(3), size_mm=(1, -1, 1), polarisation_t=(0, 0, 1)), "size_mm"),
    (lambda: cuboid_field_t(np.zeros(3), size_mm=SIZE_MM, polarisation_t=(0, np.nan, 1)), "polarisation_t"),
    (lambda: cuboid_field_t([np.inf, 0, 0], size_mm=SIZE_MM, polarisation_t=(0, 0, 1)), "points_mm"),
    (lambda: dipole_field_t(np.zeros((2, 3)), np.zeros((5, 3)), np.zeros((4, 3))), "moments_tmm3"),
    (lambda: dipole_field_t(np.zeros((2, 3)), np.zeros((5,)), np.zeros((5, 3))), "positions_mm"),
    (lambda: skin_cells(size_mm=20, thickness_mm=2.5, cell_mm=0.5, nodes=0), "nodes"),
    (lambda: skin_cells(size_mm=20, thickness_mm=2.5, cell_mm=-0.5, nodes=6), "cell_mm"),
    (lambda: skin_cells(size_mm=20, thickness_mm=0.0, cell_mm=0.5, nodes=6), "thickness_mm"),
    (lambda: skin_dipoles(skin_cells(size_mm=2, thickness_mm=1, cell_mm=1, nodes=2), (0, 1)),
     "polarisation_t"),
])
def test_bad_input_raises_value_error_naming_argument(call, name):
    with pytest.raises(ValueError, match=name):
        call()
