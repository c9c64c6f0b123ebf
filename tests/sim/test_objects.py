"""Indenters: heightmap validation, posing, built-in shape geometry, registry and STL round trips."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_manip.errors import MeshError
from tactile_manip.sim.objects import Indenter, IndenterPose
from tactile_manip.sim.shapes import SHAPES, make_indenter, procedural, procedural_sharp, ridge, rod

PX = 0.05


def _pad_grid(n: int = 200, pixel_mm: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    xs = (np.arange(n) - (n - 1) / 2) * pixel_mm
    return np.meshgrid(xs, xs[::-1])


def _assert_extent(mask: np.ndarray, axis: int, width_mm: float) -> None:
    """The pixel centres of ``mask`` along ``axis`` span ``width_mm`` as closely as a PX grid can."""
    extent = (mask.sum(axis=axis).max() - 1) * PX  # first to last covered centre
    assert width_mm - 2 * PX < extent <= width_mm + 1e-6


def _straight_section(ind: Indenter, x_mm: float = -10.0) -> np.ndarray:
    """Protrusion along local y through the bar at local x (reference-point coordinates)."""
    y = np.arange(-5.0, 5.0, PX / 4)
    return ind.protrusion_mm(np.full_like(y, x_mm), y, IndenterPose())


@pytest.mark.parametrize("height, pixel, match", [
    (np.zeros((0, 0)), 0.1, "height_mm is empty"),
    (np.zeros(5), 0.1, "2-D array"),
    (np.zeros((1, 5)), 0.1, "at least 2x2"),
    (np.full((4, 4), np.nan), 0.1, "no finite value"),
    (np.array([[0.0, np.inf], [0.0, 0.0]]), 0.1, "infinite"),
    (np.zeros((4, 4)), 0.0, "pixel_mm must be > 0"),
    (np.zeros((4, 4)), -1.0, "pixel_mm"),
    (np.zeros((4, 4)), float("nan"), "pixel_mm must be finite"),
])
def test_heightmap_validation(height: np.ndarray, pixel: float, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Indenter.from_heightmap(height, pixel)


def test_heightmap_is_read_only_copy_and_origin_checked() -> None:
    src = np.ones((3, 3))
    ind = Indenter(src, 0.1)
    src[0, 0] = 5.0
    assert ind.height_mm[0, 0] == 1.0 and ind.height_mm.dtype == np.float64
    with pytest.raises(ValueError):
        ind.height_mm[0, 0] = 2.0
    with pytest.raises(ValueError, match="origin_mm"):
        Indenter(src, 0.1, origin_mm=(0.0, np.nan))


def test_pose_validation() -> None:
    with pytest.raises(ValueError, match="tilt_x_rad"):
        IndenterPose(tilt_x_rad=0.4)
    with pytest.raises(ValueError, match="x_mm must be finite"):
        IndenterPose(x_mm=np.inf)


def test_layout_row0_is_plus_y_and_col0_is_minus_x() -> None:
    height = np.zeros((3, 3))
    height[0, 2] = 1.0  # top-right pixel: local (+1, +1) px
    ind = Indenter(height, 1.0)
    assert ind.protrusion_mm(np.array([1.0, -1.0]), np.array([1.0, -1.0]), IndenterPose()) == pytest.approx([1, 0])
    shifted = Indenter(height, 1.0, origin_mm=(1.0, 1.0))  # reference point on that pixel
    assert shifted.protrusion_mm(np.array(2.0), np.array(3.0), IndenterPose(x_mm=2.0, y_mm=3.0)) == 1.0


def test_pose_equals_rotated_translated_points() -> None:
    rng = np.random.default_rng(0)
    ind = make_indenter("letter_r")
    local = rng.uniform(-9, 9, size=(2, 500))
    yaw, tx, ty = 0.7, 1.5, -2.0
    c, s = math.cos(yaw), math.sin(yaw)
    pad_x, pad_y = c * local[0] - s * local[1] + tx, s * local[0] + c * local[1] + ty
    posed = ind.protrusion_mm(pad_x, pad_y, IndenterPose(x_mm=tx, y_mm=ty, yaw_rad=yaw))
    ref = ind.protrusion_mm(local[0], local[1], IndenterPose())
    np.testing.assert_allclose(posed, ref, atol=1e-9)


def test_tilt_adds_plane() -> None:
    ind = Indenter(np.zeros((401, 401)), PX)
    x, y = _pad_grid(50, 0.2)
    pose = IndenterPose(x_mm=1.0, y_mm=-0.5, tilt_x_rad=0.1, tilt_y_rad=-0.2)
    plane = (y + 0.5) * math.tan(0.1) - (x - 1.0) * math.tan(-0.2)
    np.testing.assert_allclose(ind.protrusion_mm(x, y, pose), plane, atol=1e-12)


def test_off_footprint_is_nan_and_fast_shape() -> None:
    ind = rod("cylinder", size_mm=4.0, length_mm=10.0)
    x, y = _pad_grid()
    p = ind.protrusion_mm(x, y, IndenterPose())
    assert p.shape == (200, 200)
    assert np.isnan(p[np.abs(y) > 2.1]).all() and np.isnan(p[np.abs(x) > 5.1]).all()
    assert np.isfinite(p[(np.abs(y) < 1.9) & (np.abs(x) < 4.9)]).all()


@pytest.mark.parametrize("kind, size, half_width", [("cylinder", 4.0, 2.0), ("square", 3.0, 1.5),
                                                    ("hex", 6.0, 6.0 / math.sqrt(3))])
def test_rod_footprint_width_and_symmetry(kind: str, size: float, half_width: float) -> None:
    ind = rod(kind, size_mm=size, length_mm=20.0)
    _assert_extent(np.isfinite(ind.height_mm), 0, 2 * half_width)
    np.testing.assert_array_equal(ind.height_mm, ind.height_mm[::-1])  # mirror about the bar axis
    assert np.nanmax(ind.height_mm) == pytest.approx(size / 2)


def test_hex_flat_is_one_side_wide() -> None:
    for ind in (rod("hex", size_mm=6.0), make_indenter("allen_key", across_flats_mm=6.0, long_arm_mm=40.0)):
        prof = _straight_section(ind)
        flat = (prof > np.nanmax(prof) - 1e-9).sum() * PX / 4
        assert flat == pytest.approx(6.0 / math.sqrt(3), abs=PX)
        foot = np.isfinite(prof).sum() * PX / 4  # bilinear sampling loses up to a pixel at each edge
        assert foot == pytest.approx(2 * 6.0 / math.sqrt(3), abs=2 * PX)
        assert np.nanmax(prof) - np.nanmin(prof) == pytest.approx(3.0, abs=0.1)  # half of across flats


def test_allen_key_bend_falls_off_near_origin() -> None:
    ind = make_indenter("allen_key")  # across flats 4, bend radius 4
    top = ind.protrusion_mm(np.array([-10.0, 0.0, 3.0, 5.5, 6.2]), np.zeros(5), IndenterPose())
    assert top[0] == pytest.approx(2.0) and top[1] == pytest.approx(2.0)
    assert top[2] < top[1] - 0.5 and top[3] < top[2]  # the bend lifts away from the pad
    assert np.isnan(top[4])  # past the outside of the bend


def test_letter_r_relief_and_plate() -> None:
    ind = make_indenter("letter_r", relief_mm=1.5)
    assert ind.relief_mm == pytest.approx(1.5, abs=1e-9)
    assert np.isfinite(ind.height_mm).all() and ind.height_mm.shape[0] * PX >= 30.0
    assert ind.height_mm[0, 0] == 0.0
    raised = ind.height_mm > 0.75
    rows, cols = np.nonzero(raised)
    assert (rows.max() - rows.min() + 1) * PX == pytest.approx(12.0, abs=2 * PX)
    assert not np.array_equal(raised, raised[::-1]) and not np.array_equal(raised, raised[:, ::-1])


def test_procedural_seeded() -> None:
    a, b, c = procedural(3), procedural(3), procedural(4)
    np.testing.assert_array_equal(a.height_mm, b.height_mm)
    assert not np.array_equal(np.nan_to_num(a.height_mm, nan=-1), np.nan_to_num(c.height_mm, nan=-1))
    for seed in range(20):
        height = procedural(seed).height_mm
        assert 0.0 <= np.nanmin(height) and np.nanmax(height) <= 2.5
        if np.isfinite(height).all():  # on a base plate at 0: the relief is the tallest part
            assert 0.5 <= np.nanmax(height)
    with pytest.raises(ValueError, match="seed"):
        procedural(-1)


@pytest.mark.parametrize("angle, radius", [(60.0, 0.0), (90.0, 0.3), (120.0, 1.0)])
def test_ridge_is_a_wedge_of_its_apex_angle(angle: float, radius: float) -> None:
    ind = ridge(angle_deg=angle, tip_radius_mm=radius, height_mm=2.0, length_mm=20.0)
    h = ind.height_mm
    np.testing.assert_allclose(h, h[::-1], atol=1e-12)  # mirror about the edge
    half = math.radians(angle) / 2
    assert np.nanmax(h) == pytest.approx(2.0 - radius * (1 / math.sin(half) - 1), abs=1e-3)
    half_width = 2.0 * math.tan(math.radians(angle) / 2)  # flanks reach the base at height tan(angle / 2)
    _assert_extent(np.isfinite(h), 0, 2 * half_width)
    col = h[:, h.shape[1] // 2]
    finite = np.isfinite(col)
    slope = np.abs(np.diff(col[finite])) / PX
    if radius == 0.0:  # flanks straight to the apex: |dh/dy| = 1 / tan(angle / 2) everywhere
        np.testing.assert_allclose(np.median(slope), 1 / math.tan(math.radians(angle) / 2), rtol=0.05)
    else:  # the rounded tip is flat at the top, the flanks keep their slope below it
        assert slope.min() < 0.2 and slope.max() == pytest.approx(1 / math.tan(math.radians(angle) / 2), rel=0.05)
    with pytest.raises(ValueError, match="angle_deg"):
        ridge(angle_deg=5.0)


def test_procedural_sharp_is_seeded_sharp_and_separate_from_procedural() -> None:
    a, b = procedural_sharp(3), procedural_sharp(3)
    np.testing.assert_array_equal(a.height_mm, b.height_mm)
    assert not np.array_equal(np.nan_to_num(a.height_mm, nan=-1), np.nan_to_num(procedural(3).height_mm, nan=-1))
    for seed in range(9000, 9400):  # every seed of the robust training family has material
        assert np.isfinite(procedural_sharp(seed).height_mm).any(), seed
    steep = 0
    for seed in range(10):
        h = procedural_sharp(seed).height_mm
        assert 0.0 <= np.nanmin(h) and np.nanmax(h) <= 2.5
        grad = np.hypot(*np.gradient(np.nan_to_num(h, nan=0.0), PX))
        steep += np.nanmax(np.where(np.isfinite(h), grad, 0)) > 1.5  # flanks steeper than 56 deg somewhere
    assert steep >= 8


def test_registry() -> None:
    assert set(SHAPES) == {"allen_key", "letter_r", "cylinder", "hex_bar", "square_bar", "procedural", "ridge",
                           "procedural_sharp", "flat_bar", "procedural_bar", "procedural_prism"}
    assert make_indenter("hex_bar", size_mm=5.0).name == "hex_bar"
    with pytest.raises(ValueError, match="unknown object 'banana'; known: allen_key"):
        make_indenter("banana")
    with pytest.raises(ValueError, match="size_mm must be <= 8.0"):
        make_indenter("cylinder", size_mm=9.0)


def test_stl_round_trip_box_and_cylinder(tmp_path) -> None:
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box(extents=(10.0, 6.0, 2.0))
    box.export(tmp_path / "box.stl")
    ind = Indenter.from_mesh(tmp_path / "box.stl")
    assert ind.name == "box"
    fin = np.isfinite(ind.height_mm)
    _assert_extent(fin, 1, 10.0)
    _assert_extent(fin, 0, 6.0)
    np.testing.assert_allclose(ind.height_mm[fin], 1.0, atol=1e-9)  # bottom face at z = -1

    cyl = trimesh.creation.cylinder(radius=2.0, height=16.0, sections=256)
    cyl.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [0, 1, 0]))  # axis along x
    cyl.export(tmp_path / "cyl.stl")
    ind = Indenter.from_mesh(tmp_path / "cyl.stl")
    y = np.linspace(-1.9, 1.9, 77)
    got = ind.protrusion_mm(np.zeros_like(y), y, IndenterPose())
    np.testing.assert_allclose(got, np.sqrt(4.0 - y**2), atol=0.02)
    _assert_extent(np.isfinite(ind.height_mm), 0, 4.0)


def test_malformed_meshes_raise_mesh_error(tmp_path) -> None:
    trimesh = pytest.importorskip("trimesh")
    (tmp_path / "garbage.stl").write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 300, dtype=np.uint8)))
    (tmp_path / "empty.stl").write_bytes(b"")
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    vertices = box.vertices.copy()
    vertices[0] = np.nan
    trimesh.Trimesh(vertices, box.faces, process=False).export(tmp_path / "nan.stl")
    for name in ("garbage.stl", "empty.stl", "nan.stl", "missing.stl"):
        with pytest.raises(MeshError, match=name):
            Indenter.from_mesh(tmp_path / name)
    with pytest.raises(ValueError, match="pixel_mm"):
        box.export(tmp_path / "box.stl")
        Indenter.from_mesh(tmp_path / "box.stl", pixel_mm=1e-4)
