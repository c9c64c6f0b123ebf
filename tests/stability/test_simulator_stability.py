"""Stability of the paired-sensor simulator: the contact solver's hard geometries and float32 inputs.

Expected behaviours: the solver converges (no SimulationError) with the force balance ``sum(p) dA = F`` to
1e-9, finite non-negative pressure, and the known closed forms; float32 inputs give the float64 result to a
stated tolerance (bit for bit where the values are the same, since inputs are coerced to float64 at the edge).

Already covered in tests/sim/test_contact.py: a square flat punch (converges, finite, edge peak > 1.5x centre,
area), a flat plate over the whole grid (all in contact, approach > 0), Hertz, force balance and
complementarity on a cylinder, non-convergence as a SimulationError. In tests/sim/test_chip.py: float32 and
float64 fields give the same counts. Here: the flat-ended *cylinder* against Boussinesq, the edge singularity
growing with refinement, force balance and positivity on both hard geometries, a plate larger than the pad
through the whole SensorPair, and float32 heightmaps, poses, gaps, pressures and wavenumbers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_manip.perception.pose import angle_from_image
from tactile_manip.sim.contact import ContactSolution, solve_contact
from tactile_manip.sim.deformation import layer_fields
from tactile_manip.sim.layer import compliance
from tactile_manip.sim.objects import Indenter, IndenterPose
from tactile_manip.sim.pair import PairedSample, SensorPair
from tactile_manip.sim.shapes import make_indenter
from tactile_manip.sim.vbts import dtact_depth

SKIN_E_MPA, LAYER_H_MM = 0.2, 2.5
PUNCH_RADIUS_MM = 3.0
FORCE_BALANCE_RTOL = 1e-9


def _grid(n: int, pixel_mm: float) -> tuple[np.ndarray, np.ndarray]:
    c = (np.arange(n) - (n - 1) / 2) * pixel_mm
    return np.meshgrid(c, -c)


def _punch_gap(n: int, pixel_mm: float, radius_mm: float = PUNCH_RADIUS_MM) -> np.ndarray:
    """Flat-ended cylinder: zero gap over its face, no material (NaN) beyond it."""
    x, y = _grid(n, pixel_mm)
    return np.where(np.hypot(x, y) < radius_mm, 0.0, np.nan)


def _assert_valid(sol: ContactSolution, gap: np.ndarray, force_n: float) -> None:
    """Force balance, finite and non-negative pressure only where there is material, no penetration."""
    p = sol.pressure_mpa
    solid = np.isfinite(gap)
    assert np.isfinite(p).all() and np.isfinite(sol.deflection_mm).all()
    assert math.isfinite(sol.approach_mm) and sol.approach_mm > 0
    assert sol.force_n == pytest.approx(force_n, rel=FORCE_BALANCE_RTOL)
    assert (p >= 0).all() and not p[~solid].any()
    clearance = np.where(solid, gap, 0.0) + sol.deflection_mm - sol.approach_mm
    assert clearance[solid].min() > -2e-3 * sol.approach_mm


def _rim_and_centre(p: np.ndarray, n: int, pixel_mm: float) -> tuple[float, float]:
    """Mean pressure on the outermost ring of punch cells and within 1 mm of the centre."""
    x, y = _grid(n, pixel_mm)
    r = np.hypot(x, y)
    rim = (r < PUNCH_RADIUS_MM) & (r > PUNCH_RADIUS_MM - 1.5 * pixel_mm)
    return float(p[rim].mean()), float(p[r < 1.0].mean())


# ---------------------------------------------------------------- flat punch (edge singularity)


def test_flat_cylinder_punch_on_the_skin_converges_with_the_edge_above_the_centre():
    n, pixel, force = 80, 0.25, 10.0
    gap = _punch_gap(n, pixel)
    sol = solve_contact(gap, force_n=force, modulus_mpa=SKIN_E_MPA, thickness_mm=LAYER_H_MM, pixel_mm=pixel)
    _assert_valid(sol, gap, force)
    assert (sol.pressure_mpa[np.isfinite(gap)] > 0).all()  # a flat face touches everywhere
    assert sol.contact_area_mm2 == pytest.approx(math.pi * PUNCH_RADIUS_MM**2, rel=0.02)
    rim, centre = _rim_and_centre(sol.pressure_mpa, n, pixel)
    assert rim > 1.5 * centre


def test_flat_cylinder_punch_on_a_thick_layer_matches_boussinesq():
    """Half-space (h = 1e4 mm): approach ``3F / (8 a E)`` and centre pressure ``F / (2 pi a^2)``
    (Boussinesq's rigid flat punch, nu = 0.5). Tolerances 2 % and 6 % at 0.1 mm cells."""
    n, pixel, force = 120, 0.1, 1.0
    gap = _punch_gap(n, pixel)
    sol = solve_contact(gap, force_n=force, modulus_mpa=SKIN_E_MPA, thickness_mm=1e4, pixel_mm=pixel)
    _assert_valid(sol, gap, force)
    a = PUNCH_RADIUS_MM
    assert sol.approach_mm == pytest.approx(3 * force / (8 * a * SKIN_E_MPA), rel=0.02)
    _, centre = _rim_and_centre(sol.pressure_mpa, n, pixel)
    assert centre == pytest.approx(force / (2 * math.pi * a * a), rel=0.06)


def test_flat_punch_edge_peak_grows_with_refinement_as_a_singularity_should():
    ratios = []
    for n, pixel in ((48, 0.25), (120, 0.1)):
        gap = _punch_gap(n, pixel)
        sol = solve_contact(gap, force_n=1.0, modulus_mpa=SKIN_E_MPA, thickness_mm=1e4, pixel_mm=pixel)
        _assert_valid(sol, gap, 1.0)
        rim, centre = _rim_and_centre(sol.pressure_mpa, n, pixel)
        ratios.append(rim / centre)
    assert ratios[1] > 1.3 * ratios[0] > 1.3 * 2.0  # bounded peaks would not grow: a singular edge does


# ---------------------------------------------------------------- an object larger than the pad


def test_plate_over_the_whole_grid_converges_with_force_balance():
    n, pixel, force = 80, 0.25, 10.0
    gap = np.zeros((n, n))
    sol = solve_contact(gap, force_n=force, modulus_mpa=SKIN_E_MPA, thickness_mm=LAYER_H_MM, pixel_mm=pixel)
    _assert_valid(sol, gap, force)
    assert sol.contact_mask.all() and (sol.pressure_mpa > 0).all()
    assert sol.pressure_mpa[:, 0].mean() > sol.pressure_mpa[n // 2 - 2:n // 2 + 2, n // 2 - 2:n // 2 + 2].mean()


@pytest.fixture(scope="module")
def pair() -> SensorPair:
    return SensorPair(seed=0)


def test_plate_larger_than_the_pad_through_the_sensor_pair(pair):
    """A 30 x 30 mm flat plate centred on the 20 x 20 mm pad at 10 N. Expected: a valid sample in contact
    everywhere, mean pressure x pad area = force, a finite reading, and an undefined angle in the VBTS truth
    (a uniform shallow imprint has no axis)."""
    plate = Indenter(np.zeros((61, 61)), 0.5, name="plate_30mm")
    s = pair.press(plate, IndenterPose(), 10.0, np.random.default_rng(0))
    pad_mm2 = pair.board.layer.size_mm[0] * pair.board.layer.size_mm[1]
    assert s.contact and s.contact_mask.all() and s.force_n == 10.0
    assert s.pressure.area_mm2 == pytest.approx(pad_mm2)
    assert s.pressure.mean_kpa * 1e-3 * s.pressure.area_mm2 == pytest.approx(10.0, rel=1e-9)
    assert np.isfinite(s.field_ut).all() and np.isfinite(s.depth_mm).all() and not s.saturated.any()
    assert 0.0 < s.approach_mm < 0.5
    truth = angle_from_image(s.depth_mm, pixel_mm=pair.params.vbts.pixel_mm)
    assert not truth.defined and truth.reason


def test_flat_cylinder_through_the_sensor_pair_is_round_in_the_truth(pair):
    """A 6 mm flat-ended cylinder standing on the pad: contact over its face, an edge pressure peak well above
    the mean, and an isotropic (undefined) truth angle."""
    x, y = _grid(161, 0.05)
    punch = Indenter(np.where(np.hypot(x, y) <= PUNCH_RADIUS_MM, 0.0, np.nan), 0.05, name="flat_cylinder_6mm")
    s = pair.press(punch, IndenterPose(), 10.0, np.random.default_rng(0))
    assert s.contact and np.isfinite(s.field_ut).all()
    assert s.pressure.area_mm2 == pytest.approx(math.pi * PUNCH_RADIUS_MM**2, rel=0.03)
    assert s.pressure.peak_kpa > 2.0 * s.pressure.mean_kpa
    truth = angle_from_image(s.depth_mm, pixel_mm=pair.params.vbts.pixel_mm)
    assert not truth.defined and "isotropic" in truth.reason


# ---------------------------------------------------------------- float32 against float64


def _cylinder_gap(n: int, pixel_mm: float, diameter_mm: float) -> np.ndarray:
    _, y = _grid(n, pixel_mm)
    r = diameter_mm / 2
    return np.where(np.abs(y) < r, r - np.sqrt(np.clip(r * r - y * y, 0, None)), np.nan)


def test_contact_solver_float32_gap_agrees_with_float64():
    """Same values in float32 and float64: bit-identical. Against the unrounded float64 gap: approach within
    1e-6 relative, pressure within 1e-5 of its peak."""
    gap64 = _cylinder_gap(80, 0.25, 5.0)
    gap32 = gap64.astype(np.float32)
    args = dict(force_n=10.0, modulus_mpa=SKIN_E_MPA, thickness_mm=LAYER_H_MM, pixel_mm=0.25)
    s32 = solve_contact(gap32, **args)
    s32_as_64 = solve_contact(gap32.astype(np.float64), **args)
    s64 = solve_contact(gap64, **args)
    np.testing.assert_array_equal(s32.pressure_mpa, s32_as_64.pressure_mpa)
    assert s32.approach_mm == s32_as_64.approach_mm
    assert s32.approach_mm == pytest.approx(s64.approach_mm, rel=1e-6)
    np.testing.assert_allclose(s32.pressure_mpa, s64.pressure_mpa, atol=1e-5 * s64.pressure_mpa.max())
    _assert_valid(s32, gap32, 10.0)


def test_layer_compliance_and_fields_float32_agree_with_float64():
    k64 = np.geomspace(1e-4, 1e3, 200)
    k32 = k64.astype(np.float32)
    c32 = compliance(k32, thickness_mm=np.float32(LAYER_H_MM), modulus_mpa=np.float32(SKIN_E_MPA))
    assert c32.dtype == np.float64 and np.isfinite(c32).all()
    np.testing.assert_array_equal(c32, compliance(k32.astype(np.float64), thickness_mm=LAYER_H_MM,
                                                  modulus_mpa=float(np.float32(SKIN_E_MPA))))
    np.testing.assert_allclose(c32, compliance(k64, thickness_mm=LAYER_H_MM, modulus_mpa=SKIN_E_MPA), rtol=1e-6)
    x, y = _grid(48, 0.25)
    p = np.exp(-((x - 1.0) ** 2 + y**2) / 2.0)
    u64, g64 = layer_fields(p, cell_mm=0.25, z_mm=np.array([-1.0, 0.0]), thickness_mm=LAYER_H_MM,
                            modulus_mpa=SKIN_E_MPA)
    u32, g32 = layer_fields(p.astype(np.float32), cell_mm=0.25, z_mm=np.array([-1.0, 0.0]),
                            thickness_mm=LAYER_H_MM, modulus_mpa=SKIN_E_MPA)
    assert np.isfinite(u32).all() and np.isfinite(g32).all()
    assert np.abs(u32 - u64).max() < 1e-6 * np.abs(u64).max()
    assert np.abs(g32 - g64).max() < 1e-6 * np.abs(g64).max()


def _press(pair: SensorPair, indenter: Indenter, pose: IndenterPose) -> PairedSample:
    return pair.press(indenter, pose, 10.0, np.random.default_rng(1))


def test_float32_heightmap_gives_the_float64_sample(pair):
    """A float32 heightmap equals the float64 one holding the same values, bit for bit; against the unrounded
    float64 heightmap: approach within 1e-6 relative, noise-free field change within 1e-3 uT, the quantised
    reading within one z LSB (0.323 uT), the imprint within 1e-5 mm."""
    rod = make_indenter("hex_bar", size_mm=4.0)
    as32 = Indenter(rod.height_mm.astype(np.float32), rod.pixel_mm, origin_mm=rod.origin_mm)
    as32_in_64 = Indenter(rod.height_mm.astype(np.float32).astype(np.float64), rod.pixel_mm, origin_mm=rod.origin_mm)
    pose = IndenterPose(0.5, -0.5, 0.3)
    s64, s32, s32_in_64 = _press(pair, rod, pose), _press(pair, as32, pose), _press(pair, as32_in_64, pose)
    for name in ("field_ut", "field_change_ut", "imprint_mm", "depth_mm"):
        np.testing.assert_array_equal(getattr(s32, name), getattr(s32_in_64, name), err_msg=name)
    assert s32.approach_mm == pytest.approx(s64.approach_mm, rel=1e-6)
    np.testing.assert_allclose(s32.field_change_ut, s64.field_change_ut, atol=1e-3)
    np.testing.assert_allclose(s32.field_ut, s64.field_ut, atol=pair.params.chip.lsb_z_ut + 1e-6)
    np.testing.assert_allclose(s32.imprint_mm, s64.imprint_mm, atol=1e-5)
    assert np.abs(s64.field_change_ut).max() > 50.0  # a real press, not an empty one


def test_float32_pose_values_give_the_float64_sample(pair):
    """An IndenterPose given numpy float32 values: the sample of the same values as Python floats, bit for bit."""
    rod = make_indenter("hex_bar", size_mm=4.0)
    values = np.array([0.5, -0.5, 1.5707, 0.01, -0.02], np.float32)  # yaw near the +90 degree seam
    s32 = _press(pair, rod, IndenterPose(*values))
    s64 = _press(pair, rod, IndenterPose(*(float(v) for v in values)))
    for name in ("field_ut", "field_change_ut", "imprint_mm", "depth_mm"):
        np.testing.assert_array_equal(getattr(s32, name), getattr(s64, name), err_msg=name)
    assert s32.approach_mm == s64.approach_mm and s32.contact


@pytest.mark.parametrize("field, value", [("x_mm", np.float32("nan")), ("yaw_rad", np.float32("inf")),
                                          ("tilt_x_rad", np.float32(0.5))])
def test_bad_float32_pose_values_are_named_errors(field, value):
    with pytest.raises(ValueError, match=f"IndenterPose.{field}"):
        IndenterPose(**{field: value})


def test_vbts_and_magnetic_skin_float32_inputs_agree(pair):
    rod = make_indenter("hex_bar", size_mm=4.0)
    s = _press(pair, rod, IndenterPose(0.5, -0.5, 0.3))
    imprint64 = s.imprint_mm.astype(np.float64)
    np.testing.assert_array_equal(dtact_depth(s.imprint_mm, pair.params.vbts, np.random.default_rng(0)),
                                  dtact_depth(imprint64, pair.params.vbts, np.random.default_rng(0)))
    gap_c, _ = pair._gaps(rod, s.pose)
    sol = pair._solve(gap_c, 10.0, pair.params.layer.skin_modulus_kpa)
    b64 = pair.skin.field_change_t(sol.pressure_mpa, sol.pixel_mm) * 1e6
    b32 = pair.skin.field_change_t(sol.pressure_mpa.astype(np.float32), sol.pixel_mm) * 1e6
    assert np.isfinite(b32).all() and np.abs(b32 - b64).max() < 1e-3  # uT, of a ~250 uT change
