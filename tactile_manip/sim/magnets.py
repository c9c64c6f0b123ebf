"""Closed-form fields of discrete permanent magnets: axially polarised cylinders and cuboids, at any pose.

Lengths are millimetres and fields tesla, as in :mod:`tactile_manip.sim.magnetics`. A magnet is described in
its own frame (centre at the origin, a cylinder's axis along z); :func:`magnet_field_t` places it at a centre
and a rotation, so a magnet that the layer moves and turns under a press keeps an exact field.

The cylinder is Derby and Olbert's form (Am. J. Phys. 78, 229 (2010)): the field of a uniformly axially
magnetised cylinder in terms of Bulirsch's general complete elliptic integral ``cel``, evaluated by his
iteration (Numer. Math. 13, 305 (1969)); it holds everywhere off the magnet's rims, inside included.
"""

from __future__ import annotations

import numpy as np

from tactile_manip.checks import check_array, check_finite_scalar
from tactile_manip.sim.magnetics import cuboid_field_t

_CEL_TOLERANCE = 1e-13
_CEL_MAX_ITERATIONS = 40  # the iteration doubles its digits each step: 6-8 steps reach float64
_RIM_KC = 1e-12           # cel's modulus on a cylinder's rim, where the field diverges (kept finite)


def cel(kc: np.ndarray, p: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Bulirsch's general complete elliptic integral, elementwise over broadcast arrays (``kc != 0``, ``p >= 0``).

    ``cel(kc, p, c, s) = int_0^{pi/2} (c cos^2 t + s sin^2 t) /
    ((cos^2 t + p sin^2 t) sqrt(cos^2 t + kc^2 sin^2 t)) dt``.
    """
    kc, p, c, s = (np.array(v, dtype=np.float64) for v in np.broadcast_arrays(kc, p, c, s))
    k = np.abs(kc)
    positive = p > 0.0
    # start values: p > 0 directly; p = 0 (a point on the cylinder's mantle) by Bulirsch's transformation
    g = np.where(positive, 1.0, 1.0 - p)  # the p > 0 lanes take the other branch; keep their divisions finite
    f = kc * kc - p
    q = (1.0 - kc * kc) * (s - c * p)
    pp = np.sqrt(np.where(positive, p, f / g))
    cc = np.where(positive, c, (c - s) / g)
    ss = np.where(positive, s / pp, -q / (g * g * pp) + cc * pp)
    em = np.ones_like(k)
    for _ in range(_CEL_MAX_ITERATIONS):
        kk = k * em  # the first pass: k itself
        f = cc
        cc = cc + ss / pp
        g = kk / pp
        ss = 2.0 * (ss + f * g)
        pp = g + pp
        g = em
        em = k + em
        if np.all(np.abs(g - k) <= g * _CEL_TOLERANCE):
            break
        k = 2.0 * np.sqrt(kk)
    return (np.pi / 2.0) * (ss + cc * em) / (em * (em + pp))


def cylinder_field_t(points_mm: object, *, diameter_mm: float, height_mm: float, polarisation_t: float
                     ) -> np.ndarray:
    """Exact B field (tesla) of a cylinder centred at the origin, axis along z, polarised along its axis.

    Args:
        points_mm: (N, 3) field points in the magnet's frame, mm.
        diameter_mm, height_mm: the cylinder's size, mm.
        polarisation_t: J = mu0 M along +z, tesla (negative: along -z).

    Returns:
        (N, 3) field, tesla (``B = mu0 (H + M)``, so inside the magnet too). On the rims (the two circular
        edges) the exact field diverges; there it is large but finite.
    """
    pts = check_array("points_mm", points_mm, shape=(None, 3))
    radius = check_finite_scalar("diameter_mm", diameter_mm, low=0.0, low_open=True) / 2.0
    half = check_finite_scalar("height_mm", height_mm, low=0.0, low_open=True) / 2.0
    b0 = check_finite_scalar("polarisation_t", polarisation_t) / np.pi
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    rho = np.hypot(x, y)
    gamma = (radius - rho) / (radius + rho)
    out = np.zeros_like(pts)
    b_rho = np.zeros_like(rho)
    for sign, zz in ((1.0, z + half), (-1.0, z - half)):
        alpha = 1.0 / np.sqrt(zz * zz + (rho + radius) ** 2)
        kc = np.maximum(np.sqrt((zz * zz + (radius - rho) ** 2)) * alpha, _RIM_KC)
        b_rho += sign * radius * alpha * cel(kc, 1.0, 1.0, -1.0)
        out[:, 2] += sign * zz * alpha * cel(kc, gamma * gamma, 1.0, gamma)
    out[:, 2] *= b0 * radius / (radius + rho)
    b_rho *= b0
    with np.errstate(invalid="ignore", divide="ignore"):
        cos, sin = np.where(rho > 0, x / rho, 0.0), np.where(rho > 0, y / rho, 0.0)
    out[:, 0], out[:, 1] = b_rho * cos, b_rho * sin
    return out


def magnet_field_t(points_mm: object, *, shape: str, size_mm: tuple[float, ...], polarisation_t: object,
                   centre_mm: object = (0.0, 0.0, 0.0), rotation: np.ndarray | None = None) -> np.ndarray:
    """B field (tesla) at (N, 3) points (mm) of one magnet at ``centre_mm``, turned by ``rotation``.

    Args:
        shape: "cylinder" (``size_mm`` = (diameter, height), axis along the magnet frame's z, polarised
            along it) or "cuboid" (``size_mm`` = (x, y, z), any polarisation).
        polarisation_t: (3,) J in the magnet's frame, tesla; a cylinder's must lie along its axis, (0, 0, J).
        rotation: (3, 3) magnet frame -> pad frame (None: aligned with the pad).
    """
    pts = check_array("points_mm", points_mm, shape=(None, 3))
    centre = check_array("centre_mm", centre_mm, shape=(3,))
    j = check_array("polarisation_t", polarisation_t, shape=(3,))
    rot = np.eye(3) if rotation is None else check_array("rotation", rotation, shape=(3, 3))
    local = (pts - centre) @ rot  # rows: R^T (p - c), the points in the magnet's frame
    if shape == "cylinder":
        if abs(j[0]) + abs(j[1]) > 1e-12 * max(1.0, abs(j[2])):
            raise ValueError(f"a cylinder's polarisation lies along its axis, (0, 0, J); got {j.tolist()}")
        field = cylinder_field_t(local, diameter_mm=size_mm[0], height_mm=size_mm[1], polarisation_t=j[2])
    elif shape == "cuboid":
        field = cuboid_field_t(local, size_mm=size_mm, polarisation_t=j)
    else:
        raise ValueError(f"shape must be 'cylinder' or 'cuboid', got {shape!r}")
    return field @ rot.T
