"""Magnetostatics of the magnetised skin: closed-form cuboid field and dipole-cell sums.

Lengths are millimetres, fields and polarisations tesla. A polarisation ``J = mu0 * M`` (tesla) times a
volume (mm^3) gives a moment in T*mm^3, and the field of such a moment at a distance in mm is in tesla
(``B = (1 / 4 pi) (3 (m.r^) r^ - m) / r^3``): the mm^3 cancel, so no unit conversion appears anywhere.

The pad frame (docs/design.md, Conventions): origin at the pad centre on the undeformed top surface, z along the outward
normal, the skin occupying ``z in [-thickness, 0]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile_manip.checks import check_array, check_finite_scalar

_FOUR_PI = 4.0 * np.pi
# Sign (-1)^(i+j+k) of each cuboid corner; index 0 is the lower bound of an axis, 1 the upper.
_CORNER_SIGN = np.array([[[1.0, -1.0], [-1.0, 1.0]], [[-1.0, 1.0], [1.0, -1.0]]])
# (point, dipole) pairs per chunk: the (N, chunk) float64 temporaries (256 kB each) stay in cache, which
# is ~3x faster than large chunks, and memory stays ~2 MB whatever M.
_PAIRS_PER_CHUNK = 32_768


def _points(name: str, points_mm: object) -> tuple[np.ndarray, bool]:
    """Return points as (N, 3) float64 and whether the input was a single (3,) point."""
    arr = check_array(name, points_mm)
    if arr.shape == (3,):
        return arr[None, :], True
    return check_array(name, arr, shape=(None, 3)), False


def _log_term(q: np.ndarray, r: np.ndarray, rho2: np.ndarray) -> np.ndarray:
    """``ln(q + R)`` with ``R = sqrt(q^2 + rho2)``, computed without cancellation when ``q < 0``.

    For ``q < 0`` it uses ``ln(q + R) = ln(rho2) - ln(R - q)``. Where the argument of a logarithm is zero
    (the point lies on an edge line of the cuboid) that logarithm is replaced by 0: on the edge line
    outside the cuboid these terms cancel exactly between corners, on the edge itself the field diverges.
    """
    neg = q < 0.0
    arg = np.where(neg, r - q, q + r)
    log_arg = np.log(np.where(arg > 0.0, arg, 1.0))
    log_rho2 = np.log(np.where(rho2 > 0.0, rho2, 1.0))
    return np.where(neg, log_rho2 - log_arg, log_arg)


def _atan_term(a: np.ndarray, b: np.ndarray, w: np.ndarray, r: np.ndarray, w_sign_at_zero: np.ndarray
               ) -> np.ndarray:
    """``atan(a b / (w R))``, with ``w = 0`` taken as the limit from the side ``w_sign_at_zero``."""
    s = np.where(w > 0.0, 1.0, np.where(w < 0.0, -1.0, w_sign_at_zero))
    return np.arctan2(a * b * s, np.abs(w) * r)


def cuboid_field_t(points_mm: object, *, size_mm: object, centre_mm: object = (0.0, 0.0, 0.0),
                   polarisation_t: object) -> np.ndarray:
    """Exact B field (tesla) of a uniformly polarised, axis-aligned cuboid.

    The field is the Coulomb field of the surface charges ``J.n`` on the six faces, each face integral
    written in closed form as a signed sum over the eight corners of ``atan`` (normal component) and
    ``ln`` (in-plane components) terms; the logarithms are evaluated in a cancellation-free form. At
    points strictly inside the cuboid ``J`` is added, so the result is ``B = mu0 (H + M)`` everywhere.

    Behaviour on the boundary: a point on a face is treated as outside and gets the one-sided limit of
    the field from outside (finite). On an edge or corner the exact field diverges logarithmically; the
    divergent terms are dropped, so the value is finite but not physically meaningful there.

    Args:
        points_mm: (N, 3) or (3,) field points, mm.
        size_mm: (3,) full edge lengths, mm, all > 0.
        centre_mm: (3,) centre of the cuboid, mm.
        polarisation_t: (3,) polarisation ``J = mu0 M``, tesla.

    Returns:
        (N, 3) field in tesla, or (3,) for a single (3,) point.
    """
    pts, single = _points("points_mm", points_mm)
    size = check_array("size_mm", size_mm, shape=(3,))
    if not np.all(size > 0.0):
        raise ValueError(f"size_mm must have three edge lengths > 0 mm, got {size.tolist()}")
    centre = check_array("centre_mm", centre_mm, shape=(3,))
    j = check_array("polarisation_t", polarisation_t, shape=(3,))
    lower, upper = centre - size / 2.0, centre + size / 2.0
    # rel[:, axis, k]: point minus the lower (k=0) and upper (k=1) bound along each axis, (N, 3, 2).
    rel = pts[:, :, None] - np.stack([lower, upper], axis=-1)[None, :, :]
    u = rel[:, 0, :, None, None]  # (N, 2, 1, 1)
    v = rel[:, 1, None, :, None]  # (N, 1, 2, 1)
    w = rel[:, 2, None, None, :]  # (N, 1, 1, 2)
    u2, v2, w2 = u * u, v * v, w * w
    r = np.sqrt(u2 + v2 + w2)  # (N, 2, 2, 2)
    outward = np.array([-1.0, 1.0])  # a face at the lower bound faces -axis, the upper one +axis
    ln_u, ln_v, ln_w = _log_term(u, r, v2 + w2), _log_term(v, r, u2 + w2), _log_term(w, r, u2 + v2)
    at_x = _atan_term(v, w, u, r, outward[:, None, None])
    at_y = _atan_term(u, w, v, r, outward[None, :, None])
    at_z = _atan_term(u, v, w, r, outward[None, None, :])
    terms = np.stack([
        -j[0] * at_x + j[1] * ln_w + j[2] * ln_v,
        j[0] * ln_w - j[1] * at_y + j[2] * ln_u,
        j[0] * ln_v + j[1] * ln_u - j[2] * at_z,
    ], axis=1)  # (N, 3, 2, 2, 2)
    field = np.einsum("nbijk,ijk->nb", terms, _CORNER_SIGN) / _FOUR_PI
    inside = np.all((pts > lower) & (pts < upper), axis=1)
    field[inside] += j
    return field[0] if single else field


def dipole_field_t(points_mm: object, positions_mm: object, moments_tmm3: object) -> np.ndarray:
    """Summed B field (tesla) of M point dipoles at N points.

    ``B(r) = (1 / 4 pi) sum_m (3 (m.r^) r^ - m) / |r|^3`` with ``r`` the point minus the dipole position
    (mm) and ``m`` the moment ``J dV`` in T*mm^3. The sum runs in chunks of dipoles so memory stays a
    few MB whatever M (16 points x 20k dipoles take a few ms). A dipole exactly at a field point
    (``r = 0``) contributes nothing.

    Args:
        points_mm: (N, 3) or (3,) field points, mm.
        positions_mm: (M, 3) dipole positions, mm.
        moments_tmm3: (M, 3) dipole moments, T*mm^3.

    Returns:
        (N, 3) field in tesla, or (3,) for a single (3,) point.
    """
    pts, single = _points("points_mm", points_mm)
    pos = check_array("positions_mm", positions_mm, shape=(None, 3))
    mom = check_array("moments_tmm3", moments_tmm3, shape=(pos.shape[0], 3))
    pos_t, mom_t = np.ascontiguousarray(pos.T), np.ascontiguousarray(mom.T)  # (3, M): fast row access
    field = np.zeros_like(pts)
    chunk = max(1, _PAIRS_PER_CHUNK // max(1, pts.shape[0]))
    for start in range(0, pos.shape[0], chunk):
        field += _dipole_chunk(pts, pos_t[:, start:start + chunk], mom_t[:, start:start + chunk])
    field /= _FOUR_PI
    return field[0] if single else field


def _dipole_chunk(pts: np.ndarray, pos_t: np.ndarray, mom_t: np.ndarray) -> np.ndarray:
    """``4 pi`` times the field at (N, 3) points of a chunk of dipoles given as (3, M) positions and moments.

    Works on three (N, M) component arrays rather than (N, M, 3) ones, to keep memory access contiguous.
    """
    d = [pts[:, a, None] - pos_t[a] for a in range(3)]  # three (N, M) separations, mm
    r2 = d[0] * d[0]
    r2 += d[1] * d[1]
    r2 += d[2] * d[2]
    with np.errstate(divide="ignore"):
        inv_r2 = 1.0 / r2
    if not np.isfinite(inv_r2).all():  # a dipole sitting on a field point: leave it out
        inv_r2[~np.isfinite(inv_r2)] = 0.0
    inv_r3 = np.sqrt(inv_r2)
    inv_r3 *= inv_r2
    c = d[0] * mom_t[0]  # becomes 3 (m.r) / r^5
    c += d[1] * mom_t[1]
    c += d[2] * mom_t[2]
    c *= inv_r2
    c *= inv_r3
    c *= 3.0
    out = np.stack([np.einsum("nm,nm->n", c, d[a]) for a in range(3)], axis=1)
    return out - inv_r3 @ mom_t.T


@dataclass(frozen=True, eq=False)
class SkinCells:
    """Discretisation of the skin ``[-s/2, s/2]^2 x [-t, 0]`` into dipole cells (read-only arrays).

    Attributes:
        cell_mm: in-plane cell edge actually used (``size_mm / round(size_mm / cell_mm)``), mm.
        xy_mm: (Ny, Nx, 2) in-plane cell centres (x, y), mm, image layout: row 0 at +y, col 0 at -x.
        z_mm: (nodes,) Gauss-Legendre node depths in ``[-thickness, 0]``, mm, ascending.
        volume_mm3: (nodes,) volume of one cell at each node (cell area x scaled GL weight), mm^3.
    """

    size_mm: float
    thickness_mm: float
    cell_mm: float
    xy_mm: np.ndarray
    z_mm: np.ndarray
    volume_mm3: np.ndarray

    @property
    def n_dipoles(self) -> int:
        """Number of dipoles ``Ny * Nx * nodes``."""
        return self.xy_mm.shape[0] * self.xy_mm.shape[1] * self.z_mm.shape[0]


def skin_cells(*, size_mm: float, thickness_mm: float, cell_mm: float, nodes: int) -> SkinCells:
    """Discretise a square skin of side ``size_mm`` and thickness ``thickness_mm`` into dipole cells.

    The in-plane grid has ``n = max(1, round(size_mm / cell_mm))`` cells per side; through the
    thickness ``nodes`` Gauss-Legendre points carry the GL weights, so ``sum(volume) * Ny * Nx`` equals
    the skin volume ``size^2 * thickness`` and the sum is exact for fields polynomial in z.
    """
    size = check_finite_scalar("size_mm", size_mm, low=0.0, low_open=True)
    thick = check_finite_scalar("thickness_mm", thickness_mm, low=0.0, low_open=True)
    cell = check_finite_scalar("cell_mm", cell_mm, low=0.0, low_open=True)
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or not 1 <= nodes <= 64:
        raise ValueError(f"nodes must be an integer in [1, 64], got {nodes!r}")
    n = max(1, int(round(size / cell)))
    cell = size / n
    centres = -size / 2.0 + (np.arange(n) + 0.5) * cell  # ascending, mm
    xx, yy = np.meshgrid(centres, centres[::-1])  # row 0 at +y
    xi, wt = np.polynomial.legendre.leggauss(int(nodes))
    z = -thick / 2.0 + xi * thick / 2.0
    volume = cell * cell * wt * thick / 2.0
    arrays = [np.stack([xx, yy], axis=-1), z, volume]
    for a in arrays:
        a.setflags(write=False)
    return SkinCells(size, thick, cell, *arrays)


def skin_dipoles(cells: SkinCells, polarisation_t: object) -> tuple[np.ndarray, np.ndarray]:
    """Positions (mm) and moments (T*mm^3) of the undeformed, uniformly polarised skin's dipole cells.

    Args:
        cells: the discretisation from :func:`skin_cells`.
        polarisation_t: (3,) uniform polarisation ``J``, tesla.

    Returns:
        positions (M, 3) in mm and moments (M, 3) in T*mm^3, ``M = Ny * Nx * nodes``, ordered as a
        C-order flattening of ``(Ny, Nx, nodes)``.
    """
    j = check_array("polarisation_t", polarisation_t, shape=(3,))
    ny, nx, _ = cells.xy_mm.shape
    nz = cells.z_mm.shape[0]
    pos = np.empty((ny, nx, nz, 3))
    pos[..., :2] = cells.xy_mm[:, :, None, :]
    pos[..., 2] = cells.z_mm
    mom = np.broadcast_to(cells.volume_mm3[:, None] * j, (ny, nx, nz, 3))
    return pos.reshape(-1, 3), mom.reshape(-1, 3).copy()
