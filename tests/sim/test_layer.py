"""The layer's compliance and internal displacement against their closed forms and limits."""

import numpy as np
import pytest

from tactile_manip.sim.deformation import layer_fields, rotate, rotation_vectors
from tactile_manip.sim.layer import compliance, profile_coefficients, vertical_profile

H_MM, E_MPA = 2.5, 0.2


def _closed_form(k, h, e):
    kh = k * h
    return 3.0 / (2.0 * e * k) * (np.sinh(2 * kh) - 2 * kh) / (np.cosh(2 * kh) + 2 * kh**2 + 1)


def test_compliance_matches_closed_form_where_direct_evaluation_is_accurate():
    k = np.geomspace(0.05, 4.0, 50)  # 0.125 < kh < 10: no cancellation, no overflow
    np.testing.assert_allclose(compliance(k, thickness_mm=H_MM, modulus_mpa=E_MPA), _closed_form(k, H_MM, E_MPA),
                               rtol=1e-8)


def test_compliance_thin_layer_limit_is_lubrication():
    k = np.array([1e-6, 1e-4, 1e-3])
    c = compliance(k, thickness_mm=H_MM, modulus_mpa=E_MPA)
    # next term of the series is O((kh)^2)
    np.testing.assert_allclose(c, k**2 * H_MM**3 / E_MPA, rtol=3 * (k[-1] * H_MM) ** 2)


def test_compliance_thick_limit_is_incompressible_half_space():
    k = np.array([20.0, 100.0, 1e4])  # kh >= 50
    c = compliance(k, thickness_mm=H_MM, modulus_mpa=E_MPA)
    np.testing.assert_allclose(c, 1.5 / (E_MPA * k), rtol=1e-12)


def test_compliance_is_finite_for_extreme_values_and_zero_at_k0():
    k = np.array([0.0, 1e-300, 1e-12, 1.0, 1e300])
    for h in (1e-6, 2.5, 1e6):
        c = compliance(k, thickness_mm=h, modulus_mpa=E_MPA)
        assert np.isfinite(c).all() and (c >= 0).all()
        assert c[0] == 0.0


@pytest.mark.parametrize("bad", [0.0, -1.0, np.nan, np.inf])
def test_compliance_refuses_bad_parameters(bad):
    with pytest.raises(ValueError, match="thickness_mm"):
        compliance(np.array([1.0]), thickness_mm=bad, modulus_mpa=E_MPA)
    with pytest.raises(ValueError, match="modulus_mpa"):
        compliance(np.array([1.0]), thickness_mm=H_MM, modulus_mpa=bad)


def test_internal_profile_meets_surface_compliance_and_boundary_conditions():
    k = np.geomspace(0.02, 30.0, 40)
    w_top, _, w2_top = vertical_profile(k, H_MM, thickness_mm=H_MM, modulus_mpa=E_MPA)
    np.testing.assert_allclose(-w_top, compliance(k, thickness_mm=H_MM, modulus_mpa=E_MPA), rtol=1e-8)
    w0, w1_0, _ = vertical_profile(k, 0.0, thickness_mm=H_MM, modulus_mpa=E_MPA)
    scale = np.abs(w_top)
    assert np.all(np.abs(w0) <= 1e-9 * scale) and np.all(np.abs(w1_0) * H_MM <= 1e-9 * scale)
    # zero shear at the top: W'' + k^2 W = 0
    np.testing.assert_allclose(w2_top, -(k**2) * w_top, rtol=1e-7, atol=1e-12)


def test_internal_profile_zero_at_k0_and_finite():
    coef = profile_coefficients(np.array([0.0, 1e-3, 50.0]), thickness_mm=H_MM, modulus_mpa=E_MPA)
    assert np.isfinite(coef).all() and np.all(coef[0] == 0)


def _bump(n=64, cell=0.25):
    c = (np.arange(n) - (n - 1) / 2) * cell
    x, y = np.meshgrid(c, -c)
    return np.exp(-((x - 1.0) ** 2 + (y + 0.5) ** 2) / 1.5), cell


def test_displacement_field_is_divergence_free_and_bonded_at_the_base():
    p, cell = _bump()
    u, grad = layer_fields(p, cell_mm=cell, z_mm=np.array([-H_MM, -1.2, 0.0]), thickness_mm=H_MM,
                           modulus_mpa=E_MPA)
    div = grad[..., 0, 0] + grad[..., 1, 1] + grad[..., 2, 2]
    assert np.abs(div).max() < 1e-9 * np.abs(grad).max()
    assert np.abs(u[0]).max() < 1e-9 * np.abs(u[2]).max()  # bonded base does not move
    assert u[2, ..., 2].min() < 0  # the loaded top moves down


def test_displacement_gradient_matches_finite_differences():
    p, cell = _bump()
    u, grad = layer_fields(p, cell_mm=cell, z_mm=np.array([-1.0]), thickness_mm=H_MM, modulus_mpa=E_MPA)
    for i in range(3):
        dx = np.gradient(u[0, ..., i], cell, axis=1)
        dy = -np.gradient(u[0, ..., i], cell, axis=0)  # row 0 is +y
        for num, ana in ((dx, grad[0, ..., i, 0]), (dy, grad[0, ..., i, 1])):
            assert np.abs(num - ana).max() < 0.03 * np.abs(ana).max()


def test_exact_rotation_preserves_length_and_matches_small_angle_limit():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(100, 3))
    big = rng.normal(size=(100, 3)) * 0.7
    np.testing.assert_allclose(np.linalg.norm(rotate(v, big), axis=1), np.linalg.norm(v, axis=1), rtol=1e-12)
    small = big * 1e-6
    np.testing.assert_allclose(rotate(v, small), v + np.cross(small, v), atol=1e-11)
    # a quarter turn about z takes x to y
    np.testing.assert_allclose(rotate(np.array([1.0, 0, 0]), np.array([0, 0, np.pi / 2])), [0, 1, 0], atol=1e-15)


def test_rotation_vector_is_half_curl():
    grad = np.zeros((3, 3))
    grad[0, 2], grad[2, 0] = 0.3, -0.1  # du_x/dz, du_z/dx
    assert rotation_vectors(grad) == pytest.approx([0.0, 0.2, 0.0])
