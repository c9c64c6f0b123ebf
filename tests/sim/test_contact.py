"""The Polonsky-Keer contact solver against Hertz, force balance, complementarity and grid invariance."""

import numpy as np
import pytest
from scipy import integrate

from tactile_manip.errors import SimulationError
from tactile_manip.sim import contact
from tactile_manip.sim.contact import love_rectangle, solve_contact
from tactile_manip.sim.layer import compliance


def _grid(n, pixel):
    c = (np.arange(n) - (n - 1) / 2) * pixel
    return np.meshgrid(c, -c)


def _sphere_gap(n, pixel, radius_mm):
    x, y = _grid(n, pixel)
    return (x**2 + y**2) / (2 * radius_mm)


@pytest.mark.parametrize("x, y", [(0.3, 0.1), (1.0, -2.0), (0.125, 0.125), (0.0, 0.4)])
def test_love_rectangle_matches_quadrature(x, y):
    half = 0.125
    val, _ = integrate.dblquad(lambda eta, xi: 1 / np.hypot(x - xi, y - eta), -half, half, -half, half,
                               epsabs=1e-11)
    assert love_rectangle(np.array(x), np.array(y), half_width_mm=half) == pytest.approx(
        val * 1.5 / (2 * np.pi), rel=1e-7)


def test_hertz_contact_radius_and_approach_on_a_thick_layer():
    radius, force, e = 10.0, 1.0, 0.2
    pixel = 0.05
    sol = solve_contact(_sphere_gap(160, pixel, radius), force_n=force, modulus_mpa=e, thickness_mm=1e4,
                        pixel_mm=pixel)
    e_star = e / 0.75
    a = (3 * force * radius / (4 * e_star)) ** (1 / 3)
    a_num = np.sqrt(sol.contact_area_mm2 / np.pi)
    assert a_num == pytest.approx(a, rel=0.02)
    assert sol.approach_mm == pytest.approx(a * a / radius, rel=0.01)
    # Hertz pressure p0 = 3F / (2 pi a^2) at the centre
    assert sol.pressure_mpa.max() == pytest.approx(3 * force / (2 * np.pi * a * a), rel=0.03)


def test_kernel_reproduces_layer_compliance_for_a_cosine_pressure():
    n, pixel = 240, 0.25
    x, _ = _grid(n, pixel)
    kfft = contact._kernel_fft(n, pixel, 2.5)
    for wavelength in (2.0, 5.0, 10.0, 20.0):
        k = 2 * np.pi / wavelength
        w = contact._convolve(np.cos(k * x), kernel_fft=kfft, n=n)
        ctr = slice(n // 2 - 8, n // 2 + 8)
        amp = np.sum(w[ctr, ctr] * np.cos(k * x[ctr, ctr])) / np.sum(np.cos(k * x[ctr, ctr]) ** 2)
        cell_average = np.sinc(k * pixel / (2 * np.pi))  # pressure is constant over each cell
        expected = compliance(np.array(k), thickness_mm=2.5, modulus_mpa=1.0) * cell_average
        assert amp == pytest.approx(expected, rel=0.01)


def test_uniform_pressure_does_not_deflect_a_bonded_incompressible_layer():
    n, pixel = 160, 0.25
    w = contact._convolve(np.ones((n, n)), kernel_fft=contact._kernel_fft(n, pixel, 2.5), n=n)
    self_deflection = contact._convolve(np.pad(np.ones((1, 1)), ((80, 79), (80, 79))),
                                        kernel_fft=contact._kernel_fft(n, pixel, 2.5), n=n).max()
    assert abs(w[n // 2, n // 2]) < 1e-3 * self_deflection * n  # C(0) = 0


def _cylinder_gap(n, pixel, diameter):
    x, y = _grid(n, pixel)
    r = diameter / 2
    return np.where(np.abs(y) < r, r - np.sqrt(np.clip(r * r - y * y, 0, None)), np.nan)


def test_force_balance_complementarity_and_no_penetration():
    pixel = 0.25
    s = _cylinder_gap(80, pixel, 6.0)
    sol = solve_contact(s, force_n=10.0, modulus_mpa=0.2, thickness_mm=2.5, pixel_mm=pixel)
    assert sol.force_n == pytest.approx(10.0, rel=1e-9)
    gap = s + sol.deflection_mm - sol.approach_mm
    solid = np.isfinite(s)
    assert gap[solid].min() > -2e-3 * sol.approach_mm          # no penetration
    assert np.abs(gap[sol.contact_mask]).max() < 2e-3 * sol.approach_mm  # in contact: touching
    assert (sol.pressure_mpa >= 0).all() and not sol.pressure_mpa[~solid].any()


def test_grid_size_invariance():
    out = {}
    for pixel in (0.25, 0.125):
        n = int(round(20 / pixel))
        sol = solve_contact(_cylinder_gap(n, pixel, 5.0), force_n=10.0, modulus_mpa=0.2, thickness_mm=2.5,
                            pixel_mm=pixel)
        out[pixel] = sol
    assert out[0.25].approach_mm == pytest.approx(out[0.125].approach_mm, rel=0.01)
    assert out[0.25].contact_area_mm2 == pytest.approx(out[0.125].contact_area_mm2, rel=0.05)


def test_flat_punch_converges_with_edge_concentration():
    pixel = 0.25
    x, y = _grid(80, pixel)
    s = np.where((np.abs(x) < 3) & (np.abs(y) < 3), 0.0, np.nan)
    sol = solve_contact(s, force_n=5.0, modulus_mpa=0.2, thickness_mm=2.5, pixel_mm=pixel)
    p = sol.pressure_mpa
    assert np.isfinite(p).all() and sol.contact_area_mm2 == pytest.approx(36.0, rel=0.01)
    edge = int(np.abs(x[0] - 2.875).argmin())  # last column inside the punch, centre row
    assert p[40, edge] > 1.5 * p[40, 40]  # the edge singularity shows as a pressure peak


def test_object_larger_than_the_pad_presses_the_whole_pad():
    s = np.zeros((80, 80))  # a flat plate covering everything
    sol = solve_contact(s, force_n=10.0, modulus_mpa=0.2, thickness_mm=2.5, pixel_mm=0.25)
    assert sol.contact_mask.all() and np.isfinite(sol.approach_mm) and sol.approach_mm > 0


@pytest.mark.parametrize("kwargs, match", [
    ({"force_n": 0.0}, "force_n"), ({"force_n": -1.0}, "force_n"), ({"force_n": np.nan}, "force_n"),
    ({"modulus_mpa": np.inf}, "modulus_mpa"),
])
def test_bad_arguments_raise(kwargs, match):
    args = {"force_n": 1.0, "modulus_mpa": 0.2, "thickness_mm": 2.5, "pixel_mm": 0.25} | kwargs
    with pytest.raises(ValueError, match=match):
        solve_contact(np.zeros((8, 8)), **args)


def test_bad_gaps_raise():
    base = {"force_n": 1.0, "modulus_mpa": 0.2, "thickness_mm": 2.5, "pixel_mm": 0.25}
    with pytest.raises(ValueError, match="no finite cell"):
        solve_contact(np.full((8, 8), np.nan), **base)
    with pytest.raises(ValueError, match="square"):
        solve_contact(np.zeros((8, 9)), **base)
    with pytest.raises(ValueError, match=">= 0"):
        solve_contact(-np.ones((8, 8)), **base)
    with pytest.raises(ValueError, match="infinite"):
        solve_contact(np.full((8, 8), np.inf), **base)


def test_non_convergence_is_a_named_error():
    with pytest.raises(SimulationError, match="did not converge"):
        solve_contact(_cylinder_gap(80, 0.25, 5.0), force_n=10.0, modulus_mpa=0.2, thickness_mm=2.5,
                      pixel_mm=0.25, max_iterations=2, tolerance=1e-12)
