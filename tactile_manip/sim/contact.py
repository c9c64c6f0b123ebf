"""Force-controlled frictionless contact of a rigid indenter on the bonded incompressible layer.

The pressure ``p >= 0`` on a square grid and the rigid approach ``delta`` solve the linear complementarity
problem ``gap = s + w - delta >= 0``, ``p >= 0``, ``p * gap = 0``, ``sum(p) dA = F``, where ``s`` is the
initial gap and ``w = K * p`` the surface deflection. It is solved with the constrained conjugate gradient
of Polonsky & Keer (Wear 231, 1999), the convolution done by a zero-padded FFT (exact linear convolution).

The influence kernel ``K`` (deflection at a cell centre from a unit pressure on a whole cell) is built in
real space as Love's exact solution for a uniformly loaded rectangle on the incompressible half-space plus
a smooth, radially symmetric layer correction obtained by a Hankel transform of
``C(k) - 1.5 / (E k)`` (see :mod:`tactile_manip.sim.layer`). Splitting it this way keeps the singular
near field exact and the thin-layer correction free of aliasing.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import special

from tactile_manip.checks import check_array, check_finite_scalar
from tactile_manip.errors import SimulationError
from tactile_manip.sim.layer import _NU_FACTOR, compliance

_FAR_GAP_MM = 1e6  # stands in for "no material here" inside the solver


@dataclass(frozen=True)
class ContactSolution:
    """Result of one force-controlled contact solve on an ``(n, n)`` grid.

    Attributes:
        pressure_mpa: (n, n) contact pressure, MPa (N/mm^2), >= 0.
        deflection_mm: (n, n) surface deflection into the layer, mm.
        approach_mm: rigid approach ``delta`` of the indenter past first touch, mm.
        pixel_mm: grid spacing, mm.
        iterations: conjugate-gradient iterations used.
        residual: final relative L1 change of the pressure.
    """

    pressure_mpa: np.ndarray
    deflection_mm: np.ndarray
    approach_mm: float
    pixel_mm: float
    iterations: int
    residual: float

    @property
    def contact_mask(self) -> np.ndarray:
        """(n, n) bool, cells carrying pressure."""
        return self.pressure_mpa > 0

    @property
    def force_n(self) -> float:
        """Total normal force, N."""
        return float(self.pressure_mpa.sum() * self.pixel_mm**2)

    @property
    def contact_area_mm2(self) -> float:
        """Area of the cells in contact, mm^2."""
        return float(self.contact_mask.sum() * self.pixel_mm**2)


def solve_contact(gap_mm: np.ndarray, *, force_n: float, modulus_mpa: float, thickness_mm: float,
                  pixel_mm: float, tolerance: float = 1e-5, max_iterations: int = 300,
                  initial_pressure_mpa: np.ndarray | None = None) -> ContactSolution:
    """Solve the force-controlled contact for an initial gap ``gap_mm`` (n, n), mm, NaN = no material.

    ``initial_pressure_mpa`` (n, n) warm-starts the iteration (for example with the solution of the same
    indenter on a stiffer layer); only its shape matters, it is rescaled to the force.

    Raises:
        ValueError: bad force, modulus, grid, or a gap with no finite cell or negative values.
        SimulationError: the solver did not converge in ``max_iterations``.
    """
    s = check_array("gap_mm", gap_mm, allow_nan=True)
    if s.ndim != 2 or s.shape[0] != s.shape[1]:
        raise ValueError(f"gap_mm: expected a square (n, n) array, got shape {s.shape}")
    force = check_finite_scalar("force_n", force_n, low=0.0, low_open=True)
    e = check_finite_scalar("modulus_mpa", modulus_mpa, low=0.0, low_open=True)
    solid = np.isfinite(s)
    if not solid.any():
        raise ValueError("gap_mm has no finite cell: the indenter does not cover the grid")
    if np.nanmin(s) < -1e-9:
        raise ValueError(f"gap_mm must be >= 0 (gap to first touch), got min {np.nanmin(s):.3g} mm")
    kernel_fft = _kernel_fft(s.shape[0], float(pixel_mm), float(thickness_mm)) / e
    p0 = (solid & (s <= s[solid].min() + 0.05)).astype(np.float64)  # cells near first touch
    if initial_pressure_mpa is not None:
        guess = np.where(solid, np.clip(check_array("initial_pressure_mpa", initial_pressure_mpa, shape=s.shape),
                                        0.0, None), 0.0)
        p0 = guess if guess.sum() > 0 else p0
    return _polonsky_keer(np.where(solid, s, _FAR_GAP_MM), solid, p0, kernel_fft, force / pixel_mm**2,
                          pixel_mm, tolerance, max_iterations)


def _polonsky_keer(s: np.ndarray, solid: np.ndarray, p0: np.ndarray, kernel_fft: np.ndarray, load: float,
                   pixel_mm: float, tolerance: float, max_iterations: int) -> ContactSolution:
    """Polonsky-Keer CG; ``load`` is the required sum of cell pressures (F / dA)."""
    n = s.shape[0]
    conv = functools.partial(_convolve, kernel_fft=kernel_fft, n=n)
    p = p0 * (load / p0.sum())
    t = np.zeros_like(s)
    g_old, conjugate, residual = 1.0, False, np.inf
    for it in range(1, max_iterations + 1):
        g = s + conv(p)
        on = p > 0
        g -= g[on].mean()
        g_norm = float(np.sum(g[on] ** 2))
        t = np.where(on, g + (g_norm / g_old) * t if conjugate else g, 0.0)
        g_old = g_norm
        r = conv(t)
        r -= r[on].mean()
        denom = float(np.sum(r[on] * t[on]))
        tau = float(np.sum(g[on] * t[on])) / denom if denom > 0 else 0.0
        p_old = p
        p = np.maximum(np.where(on, p - tau * t, 0.0), 0.0)
        overlap = solid & (p == 0) & (g < 0)
        conjugate = not overlap.any()
        if not conjugate:
            p[overlap] -= tau * g[overlap]
        p *= load / p.sum()
        residual = float(np.abs(p - p_old).sum() / load)
        if residual < tolerance:
            break
    else:
        raise SimulationError(f"contact solver did not converge in {max_iterations} iterations "
                              f"(residual {residual:.2e} > tolerance {tolerance:.1e}); raise "
                              "contact.max_iterations or coarsen contact.pixel_mm")
    w = conv(p)
    delta = float(np.mean((s + w)[p > 0]))
    return ContactSolution(pressure_mpa=p, deflection_mm=w, approach_mm=delta,
                           pixel_mm=pixel_mm, iterations=it, residual=residual)


def _convolve(field: np.ndarray, *, kernel_fft: np.ndarray, n: int) -> np.ndarray:
    """Linear convolution of an (n, n) field with the kernel, by zero padding to (2n, 2n)."""
    return np.fft.irfft2(np.fft.rfft2(field, s=(2 * n, 2 * n)) * kernel_fft, s=(2 * n, 2 * n))[:n, :n]


@functools.lru_cache(maxsize=16)
def _kernel_fft(n: int, pixel_mm: float, thickness_mm: float) -> np.ndarray:
    """rfft2 of the (2n, 2n) wrap-around influence kernel for E = 1 MPa, mm per MPa of cell pressure."""
    check_finite_scalar("pixel_mm", pixel_mm, low=0.0, low_open=True)
    offsets = (np.arange(2 * n) + n) % (2 * n) - n
    dx, dy = np.meshgrid(offsets * pixel_mm, offsets * pixel_mm, indexing="xy")
    half = 0.5 * pixel_mm
    # Love's rectangle is per unit cell pressure; the correction is a point-force kernel, times the cell area.
    kernel = (love_rectangle(dx, dy, half_width_mm=half)
              + layer_correction(np.hypot(dx, dy), thickness_mm) * pixel_mm**2)
    return np.fft.rfft2(kernel)


def love_rectangle(x_mm: np.ndarray, y_mm: np.ndarray, *, half_width_mm: float) -> np.ndarray:
    """Deflection (mm) of an incompressible half-space (E = 1 MPa) under 1 MPa on a centred square.

    Love (1929): ``w = 1 / (pi E*) * integral of dA / r`` with ``E* = E / (1 - nu^2) = 4E/3``.
    """
    a = half_width_mm
    total = (_love_corner(x_mm + a, y_mm + a) - _love_corner(x_mm - a, y_mm + a)
             - _love_corner(x_mm + a, y_mm - a) + _love_corner(x_mm - a, y_mm - a))
    return total * _NU_FACTOR / (2.0 * np.pi)


def _love_corner(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Antiderivative ``x asinh(y/|x|) + y asinh(x/|y|)`` of ``1/r`` over a rectangle (odd in x and y)."""
    ax, ay = np.abs(x), np.abs(y)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = np.where(ax > 0, x * np.arcsinh(y / np.where(ax > 0, ax, 1.0)), 0.0)
        t2 = np.where(ay > 0, y * np.arcsinh(x / np.where(ay > 0, ay, 1.0)), 0.0)
    return t1 + t2


def layer_correction(r_mm: np.ndarray, thickness_mm: float) -> np.ndarray:
    """Radially symmetric point-force kernel correction (mm per N, E = 1 MPa) from the layer thickness.

    ``D(r) = 1/(2 pi) int_0^inf (k C(k) - 1.5) J0(k r) dk``, tabulated on a fine radial grid and
    interpolated. The integrand vanishes like ``exp(-2kh)`` at large ``k``.
    """
    h = check_finite_scalar("thickness_mm", thickness_mm, low=0.0, low_open=True)
    r = np.asarray(r_mm, dtype=np.float64)
    r_max = float(r.max()) if r.size else 0.0
    r_table = np.linspace(0.0, r_max, max(int(r_max / min(h, 1.0) * 20), 64))
    table = _hankel_correction(r_table, h)
    return np.interp(r, r_table, table)


def _hankel_correction(r: np.ndarray, h: float) -> np.ndarray:
    k_max = 22.0 / h
    dk = min(0.1 / max(float(r.max()), 1e-9), 0.02 / h)
    nk = int(min(max(k_max / dk, 200), 400_000))
    k = (np.arange(nk) + 0.5) * (k_max / nk)  # midpoint rule
    integrand = k * compliance(k, thickness_mm=h, modulus_mpa=1.0) - _NU_FACTOR
    out = np.zeros_like(r)
    for start in range(0, nk, 8192):
        sl = slice(start, start + 8192)
        out += special.j0(np.outer(r, k[sl])) @ integrand[sl]
    return out * (k_max / nk) / (2.0 * np.pi)
