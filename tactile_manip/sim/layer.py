"""Linear elasticity of the contact module: an incompressible layer bonded to a rigid base.

The layer (thickness ``h``, Young's modulus ``E``, Poisson ratio 0.5, frictionless top) is loaded by a
normal pressure ``p`` on its top. Per in-plane wavenumber ``k = |k|`` (rad/mm) everything is closed form:

- the surface compliance ``C(k) = 3/(2 E k) (sinh 2kh - 2kh) / (cosh 2kh + 2 (kh)^2 + 1)``, ``C(0) = 0``,
  so that the surface deflection into the layer is ``w(k) = C(k) p(k)``;
- the internal displacement ``u_z(k, z) = W(z) p(k)``, ``u_h(k, z) = i k_vec W'(z) / k^2 p(k)`` with
  ``W(z) = (a1 + a2 z) e^{k(z-h)} + (a3 + a4 z) e^{-kz}``, ``z`` measured up from the bonded base, fixed by
  ``W(0) = W'(0) = 0`` (bonded), zero shear at the top and unit compressive normal traction at the top.

Units: mm, MPa (N/mm^2), N. ``E`` enters as ``modulus_mpa``; everything is linear in ``1/E``.
"""

from __future__ import annotations

import numpy as np

from tactile_manip.checks import check_finite_scalar

_NU_FACTOR = 1.5  # 2 (1 - nu^2) for nu = 0.5: half-space compliance is 1.5 / (E k)


def compliance(k_per_mm: np.ndarray, *, thickness_mm: float, modulus_mpa: float) -> np.ndarray:
    """Surface compliance ``C(k)`` in mm/MPa per unit pressure amplitude, for wavenumbers ``k`` >= 0 (rad/mm).

    Stable for all ``kh``: a series near 0, the exponentially scaled form at large ``kh``.
    Limits: ``C -> k^2 h^3 / E`` for ``kh -> 0`` (thin-layer lubrication) and ``1.5 / (E k)`` for
    ``kh -> inf`` (incompressible half-space).
    """
    h = check_finite_scalar("thickness_mm", thickness_mm, low=0.0, low_open=True)
    e = check_finite_scalar("modulus_mpa", modulus_mpa, low=0.0, low_open=True)
    k = np.abs(np.asarray(k_per_mm, dtype=np.float64))
    return _shape_factor(2.0 * k * h) * _NU_FACTOR / (e * np.where(k > 0, k, 1.0)) * (k > 0)


def _shape_factor(x: np.ndarray) -> np.ndarray:
    """``(sinh x - x) / (cosh x + x^2 / 2 + 1)``, evaluated without cancellation or overflow."""
    x = np.asarray(x, dtype=np.float64)
    out = np.empty_like(x)
    small = x < 0.5
    xs = x[small]
    # sinh x - x = x^3/6 + x^5/120 + x^7/5040 + x^9/362880 (error < 1e-12 relative for x < 0.5)
    num = xs**3 / 6.0 * (1.0 + xs**2 / 20.0 * (1.0 + xs**2 / 42.0 * (1.0 + xs**2 / 72.0)))
    out[small] = num / (np.cosh(xs) + 0.5 * xs**2 + 1.0)
    mid = ~small & (x < 80.0)  # beyond x = 80 the ratio is 1 to double precision
    xl = x[mid]
    em = np.exp(-xl)  # multiply numerator and denominator by 2 e^{-x}
    out[mid] = (1.0 - em * em - 2.0 * xl * em) / (1.0 + em * em + (xl**2 + 2.0) * em)
    out[x >= 80.0] = 1.0
    return out


def profile_coefficients(k_per_mm: np.ndarray, *, thickness_mm: float, modulus_mpa: float) -> np.ndarray:
    """Coefficients ``(a1, a2, a3, a4)`` of ``W(z)`` per wavenumber, shape ``k.shape + (4,)``.

    ``W`` is the vertical displacement (mm, positive up) for a unit compressive pressure (1 MPa) of
    wavenumber ``k``; ``k = 0`` gives zeros (a uniform pressure does not deform a bonded incompressible
    layer).
    """
    h = check_finite_scalar("thickness_mm", thickness_mm, low=0.0, low_open=True)
    mu = check_finite_scalar("modulus_mpa", modulus_mpa, low=0.0, low_open=True) / 3.0
    k = np.abs(np.asarray(k_per_mm, dtype=np.float64)).ravel()
    kk = np.where(k > 0, k, 1.0)
    e = np.exp(-kk * h)
    # Derivatives at the top (z = h) of the bases: f1 = e^{k(z-h)}, f2 = z f1, f3 = e^{-kz}, f4 = z f3.
    f = _basis(kk, h, np.full_like(kk, h))
    a = np.zeros(k.shape + (4, 4))
    a[:, 0] = np.stack([e, np.zeros_like(kk), np.ones_like(kk), np.zeros_like(kk)], axis=-1)  # W(0) = 0
    a[:, 1] = np.stack([kk * e, e, -kk, np.ones_like(kk)], axis=-1)          # W'(0) = 0
    a[:, 2] = f[2] + kk[:, None] ** 2 * f[0]                                  # W'' + k^2 W = 0 at top
    a[:, 3] = f[3] - 3.0 * kk[:, None] ** 2 * f[1]                            # W''' - 3k^2 W' = k^2/mu
    rhs = np.zeros(k.shape + (4,))
    rhs[:, 3] = kk**2 / mu
    coef = np.linalg.solve(a, rhs[..., None])[..., 0]
    coef[k == 0] = 0.0
    return coef.reshape(np.shape(k_per_mm) + (4,))


def _basis(k: np.ndarray, h: float, z: np.ndarray) -> list[np.ndarray]:
    """Values and first three z-derivatives of the four bases, each of shape ``k.shape + (4,)``."""
    ep = np.exp(k * (z - h))
    em = np.exp(-k * z)
    kz = k * z
    value = np.stack([ep, z * ep, em, z * em], axis=-1)
    d1 = np.stack([k * ep, (1 + kz) * ep, -k * em, (1 - kz) * em], axis=-1)
    d2 = np.stack([k**2 * ep, (2 * k + k * kz) * ep, k**2 * em, (-2 * k + k * kz) * em], axis=-1)
    d3 = np.stack([k**3 * ep, (3 * k**2 + k**2 * kz) * ep, -(k**3) * em, (3 * k**2 - k**2 * kz) * em], axis=-1)
    return [value, d1, d2, d3]


def vertical_profile(k_per_mm: np.ndarray, z_mm: float, *, thickness_mm: float,
                     modulus_mpa: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``W(z), W'(z), W''(z)`` per wavenumber at height ``z_mm`` above the base (0 <= z <= h).

    Units: mm/MPa, 1/MPa and 1/(MPa mm) for a unit compressive pressure amplitude.
    """
    coef = profile_coefficients(k_per_mm, thickness_mm=thickness_mm, modulus_mpa=modulus_mpa)
    k = np.abs(np.asarray(k_per_mm, dtype=np.float64))
    kk = np.where(k > 0, k, 1.0)
    f = _basis(kk, float(thickness_mm), np.full_like(kk, float(z_mm)))
    return tuple(np.sum(coef * f[i], axis=-1) for i in range(3))  # type: ignore[return-value]
