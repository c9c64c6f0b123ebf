"""The magnetic field of any described board's skin at its chips: no-contact field and change under a pressure.

A board file (:mod:`tactile_manip.boards`) gives the chips (firmware order, positions, axis maps), the compliant
layer (rectangle ``size_mm`` x ``thickness_mm``, bonded to a rigid base, chips ``gap_mm`` below it) and the
magnetic body, one of:

- ``"layer"``: the layer itself polarised along +z (ReSkin, AnySkin, SuperMag). No contact: the exact field of
  the rectangular cuboid. Under a pressure: the dipole-cell method of :mod:`tactile_manip.sim.mbts` on a
  rectangular skin; each cell moves with the layer's internal displacement ``u`` and its moment turns by the
  exact rotation of ``omega = curl(u) / 2``;
- ``"magnets"``: discrete magnets embedded in the layer (eFlesh). Each moves rigidly by ``u`` and turns by
  the rotation of ``omega``, both averaged over its footprint at its centre's depth, and its field is
  recomputed in closed form (:func:`~tactile_manip.sim.magnets.magnet_field_t`) at the new pose.

Pressures live on the skin's pad grid: a square ``(n, n)`` grid of ``pixel_mm`` centred on the pad that covers
the layer's rectangle (image layout: row 0 at +y, column 0 at -x). Fields are microtesla, in pad axes
(``*_pad_ut``) or in each chip's axes (firmware order, ``(n_chips, 3)``).
"""

from __future__ import annotations

import numpy as np

from tactile_manip.boards.load import Board
from tactile_manip.checks import check_array, check_finite_scalar
from tactile_manip.sim.deformation import layer_fields, rotate, rotation_vectors
from tactile_manip.sim.magnetics import cuboid_field_t, dipole_field_t
from tactile_manip.sim.magnets import magnet_field_t

_TESLA_TO_UT = 1e6


def rotation_matrix(omega: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation of angle ``|omega|`` (rad) about ``omega`` (..., 3), exact (Rodrigues)."""
    omega = np.asarray(omega, dtype=np.float64)
    eye = np.broadcast_to(np.eye(3), omega.shape[:-1] + (3, 3))
    # rotate() turns each row e_i into R e_i; those are R's columns
    return np.swapaxes(rotate(eye, omega[..., None, :]), -1, -2)


class BoardSkin:
    """The magnetic body of a simulatable board over its chips. Construction precomputes the rest state; no I/O.

    Args:
        board: a board whose file describes ``[body]`` and ``[layer]``.
        modulus_kpa: the layer's Young's modulus, kPa (default: the board file's).
        remanence_scale: multiplies the layer's remanence or every magnet's polarisation (a gain), > 0.
        pixel_mm: pad grid spacing, mm (default: the longer pad side / 100, at least 0.25 mm).
        cell_mm: in-plane dipole cell of a magnetised layer, mm.
        thickness_nodes: Gauss-Legendre nodes through a magnetised layer's thickness.
        gap_mm: the chips' gap below the layer's base, mm (default: the board file's).

    Attributes:
        n, pixel_mm: the pad grid's size (n x n pixels) and spacing, mm; it covers the longer pad side.
        x_mm, y_mm: (n, n) pixel centres in the pad frame, mm (row 0 at +y, column 0 at -x).
        pad_mask: (n, n) bool, pixels inside the layer's rectangle.
        chips_mm: (n_chips, 3) chip sensing points, pad frame, firmware order, mm.
        modulus_kpa: the layer's Young's modulus in use, kPa.

    Raises:
        ConfigError: the board cannot be simulated (one line, from ``board.require_simulation()``).
    """

    def __init__(self, board: Board, *, modulus_kpa: float | None = None, remanence_scale: float = 1.0,
                 pixel_mm: float | None = None, cell_mm: float = 0.5, thickness_nodes: int = 6,
                 gap_mm: float | None = None) -> None:
        board.require_simulation()
        self.board, self.layer, self.body = board, board.layer, board.body
        assert self.layer is not None and self.body is not None  # require_simulation() saw to it
        self.modulus_kpa = check_finite_scalar("modulus_kpa", self.layer.modulus_kpa if modulus_kpa is None
                                               else modulus_kpa, low=0.0, low_open=True)
        self.remanence_scale = check_finite_scalar("remanence_scale", remanence_scale, low=0.0, low_open=True)
        side = max(self.layer.size_mm)
        pixel = max(0.25, side / 100.0) if pixel_mm is None else check_finite_scalar(
            "pixel_mm", pixel_mm, low=0.0, low_open=True)
        self.n = max(2, int(round(side / pixel)))
        self.pixel_mm = side / self.n
        centres = (np.arange(self.n) - (self.n - 1) / 2.0) * self.pixel_mm
        self.x_mm, self.y_mm = np.meshgrid(centres, -centres)  # (n, n) pixel centres, row 0 at +y
        sx, sy = self.layer.size_mm
        self.pad_mask = (np.abs(self.x_mm) < sx / 2) & (np.abs(self.y_mm) < sy / 2)  # (n, n) inside the layer
        self.chips_mm = board.chip_positions_mm()
        if gap_mm is not None:
            self.chips_mm[:, 2] = -(self.layer.thickness_mm + check_finite_scalar("gap_mm", gap_mm, low=0.0))
        self._to_pad = np.stack([c.matrix() for c in board.chips])  # (n_chips, 3, 3) chip axes -> pad axes
        if self.body.kind == "layer":
            self._init_layer(float(cell_mm), int(thickness_nodes))
        else:
            self._init_magnets()

    # -- public ---------------------------------------------------------------------------------------------

    def baseline_pad_ut(self) -> np.ndarray:
        """(n_chips, 3) no-contact field at the chips, pad axes, uT (exact closed forms)."""
        if self.body.kind == "layer":
            sx, sy = self.layer.size_mm
            t = self.layer.thickness_mm
            field = cuboid_field_t(self.chips_mm, size_mm=(sx, sy, t), centre_mm=(0.0, 0.0, -t / 2),
                                   polarisation_t=self._polarisation_t)
            return field * _TESLA_TO_UT
        return self._magnets_field_ut(self._rest_centres, np.zeros((len(self._rest_centres), 3)))

    def rest_field_ut(self) -> np.ndarray:
        """(n_chips, 3) no-contact field at the chips, pad axes, uT (:meth:`baseline_pad_ut`)."""
        return self.baseline_pad_ut()

    def contact_change_ut(self, pressure_mpa: np.ndarray, pixel_mm: float) -> np.ndarray:
        """(n_chips, 3) field change at the chips (pad axes, uT) under a pressure on the pad grid, whose spacing
        ``pixel_mm`` must be this skin's."""
        if not np.isclose(pixel_mm, self.pixel_mm, rtol=1e-9, atol=0.0):
            raise ValueError(f"pressure on a {pixel_mm:g} mm grid; this skin's pad grid is {self.pixel_mm:g} mm")
        return self.field_change_pad_ut(pressure_mpa)

    def baseline_ut(self) -> np.ndarray:
        """(n_chips, 3) no-contact field in each chip's axes, uT (firmware order)."""
        return self.to_chip_axes(self.baseline_pad_ut())

    def field_change_pad_ut(self, pressure_mpa: np.ndarray) -> np.ndarray:
        """(n_chips, 3) field change at the chips (pad axes, uT) under a pressure on the pad grid.

        Args:
            pressure_mpa: (n, n) compressive pressure on the pad grid (``self.x_mm``, ``self.y_mm``), MPa.
        """
        p = check_array("pressure_mpa", pressure_mpa, shape=(self.n, self.n))
        if not p.any():
            return np.zeros((len(self.chips_mm), 3))
        if self.body.kind == "layer":
            return self._layer_change_ut(p)
        u, omega = self.magnet_motion(p)
        return self.magnets_change_pad_ut(u, omega)

    def field_change_ut(self, pressure_mpa: np.ndarray) -> np.ndarray:
        """(n_chips, 3) field change in each chip's axes, uT (firmware order); see :meth:`field_change_pad_ut`."""
        return self.to_chip_axes(self.field_change_pad_ut(pressure_mpa))

    def to_chip_axes(self, field_pad: np.ndarray) -> np.ndarray:
        """(n_chips, 3) pad-axes vectors at the chips -> each chip's axes (``chip.matrix().T @ b``)."""
        return np.einsum("nji,nj->ni", self._to_pad, field_pad)

    def to_pad_axes(self, field_chip: np.ndarray) -> np.ndarray:
        """(n_chips, 3) vectors in each chip's axes -> pad axes (``chip.matrix() @ b``)."""
        return np.einsum("nij,nj->ni", self._to_pad, field_chip)

    def magnet_motion(self, pressure_mpa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rigid motion of each magnet (body kind "magnets") under a pad pressure (MPa, (n, n)).

        Returns:
            (n_magnets, 3) displacement u, mm, and (n_magnets, 3) rotation vector omega = curl(u) / 2, rad,
            both averaged over the magnet's footprint at its centre's depth.
        """
        u, grad = layer_fields(pressure_mpa, cell_mm=self.pixel_mm, z_mm=self._depths,
                               thickness_mm=self.layer.thickness_mm, modulus_mpa=self.modulus_kpa * 1e-3)
        # (nz, n, n, ...) at the magnets' depths; each magnet's footprint weights pick its average
        u_m = np.einsum("myx,myxi->mi", self._footprints, u[self._depth_index])
        grad_m = np.einsum("myx,myxij->mij", self._footprints, grad[self._depth_index])
        return u_m, rotation_vectors(grad_m)

    def magnets_change_pad_ut(self, u_mm: np.ndarray, omega_rad: np.ndarray) -> np.ndarray:
        """(n_chips, 3) field change (pad axes, uT) when each magnet moves by ``u_mm`` and turns by ``omega_rad``.

        Args:
            u_mm: (n_magnets, 3) displacement of each magnet's centre, mm.
            omega_rad: (n_magnets, 3) rotation vector of each magnet (exact rotation, not linearised), rad.
        """
        m = len(self._rest_centres)
        u = check_array("u_mm", u_mm, shape=(m, 3))
        omega = check_array("omega_rad", omega_rad, shape=(m, 3))
        return self._magnets_field_ut(self._rest_centres + u, omega) - self._rest_field_ut

    # -- magnetised layer -----------------------------------------------------------------------------------

    def _init_layer(self, cell_mm: float, nodes: int) -> None:
        """Dipole cells of the rectangular skin: a square pitch fitted to x; in y the cell rows cover the side to
        within half a cell (the cells carry only the change; the rest field is the exact cuboid)."""
        sx, sy = self.layer.size_mm
        t = self.layer.thickness_mm
        check_finite_scalar("cell_mm", cell_mm, low=0.0, low_open=True)
        self._nx = max(1, int(round(sx / cell_mm)))
        self._cell = sx / self._nx
        self._ny = max(1, int(round(sy / self._cell)))
        xs = (np.arange(self._nx) - (self._nx - 1) / 2.0) * self._cell
        ys = -(np.arange(self._ny) - (self._ny - 1) / 2.0) * self._cell  # row 0 at +y
        xi, wt = np.polynomial.legendre.leggauss(nodes)
        self._z = -t / 2.0 + xi * t / 2.0
        volume = self._cell ** 2 * wt * t / 2.0
        self._polarisation_t = np.array([0.0, 0.0, self.body.remanence_t * self.remanence_scale])
        pos = np.empty((self._ny, self._nx, nodes, 3))
        pos[..., 0] = xs[None, :, None]
        pos[..., 1] = ys[:, None, None]
        pos[..., 2] = self._z
        self._positions = pos.reshape(-1, 3)
        self._moments = np.broadcast_to(volume[:, None] * self._polarisation_t, pos.shape).reshape(-1, 3).copy()
        self._rest_dipoles_t = dipole_field_t(self.chips_mm, self._positions, self._moments)
        # force-conserving map of pad pixels onto cells by their overlap (rows: -y ascends on both grids)
        centres = self.x_mm[0]
        self._pixels_to_cols = _overlap(centres, self.pixel_mm, self._nx, self._cell)  # (nx, n)
        self._pixels_to_rows = _overlap(centres, self.pixel_mm, self._ny, self._cell)  # (ny, n)

    def _layer_change_ut(self, pressure_mpa: np.ndarray) -> np.ndarray:
        force = np.where(self.pad_mask, pressure_mpa, 0.0) * self.pixel_mm ** 2
        cell_p = self._pixels_to_rows @ force @ self._pixels_to_cols.T / self._cell ** 2
        u, grad = layer_fields(cell_p, cell_mm=self._cell, z_mm=self._z, thickness_mm=self.layer.thickness_mm,
                               modulus_mpa=self.modulus_kpa * 1e-3)
        u = np.moveaxis(u, 0, 2).reshape(-1, 3)  # (nz, ny, nx, 3) -> the dipoles' (ny, nx, nz) order
        grad = np.moveaxis(grad, 0, 2).reshape(-1, 3, 3)
        moments = rotate(self._moments, rotation_vectors(grad))
        deformed = dipole_field_t(self.chips_mm, self._positions + u, moments)
        return (deformed - self._rest_dipoles_t) * _TESLA_TO_UT

    # -- discrete magnets -----------------------------------------------------------------------------------

    def _init_magnets(self) -> None:
        magnets = self.body.magnets
        t = self.layer.thickness_mm
        self._rest_centres = np.array([m.position_mm for m in magnets], dtype=np.float64)
        for i, z in enumerate(self._rest_centres[:, 2]):
            # the board check refuses magnets outside the layer; the layer's fields exist only inside it
            assert -t <= z <= 0.0, f"body.magnets[{i}] centre z = {z} mm lies outside the layer [-{t}, 0] mm"
        self._polarisations = np.array([m.polarisation_t for m in magnets]) * self.remanence_scale
        self._depths, self._depth_index = np.unique(self._rest_centres[:, 2], return_inverse=True)
        self._footprints = np.stack([self._footprint(m.shape, m.size_mm, c)
                                     for m, c in zip(magnets, self._rest_centres)])
        self._rest_field_ut = self._magnets_field_ut(self._rest_centres, np.zeros((len(magnets), 3)))

    def _footprint(self, shape: str, size_mm: tuple[float, ...], centre: np.ndarray) -> np.ndarray:
        """(n, n) weights summing to 1: the pad pixels under the magnet (a disc or a rectangle), or bilinear
        weights at its centre when it covers no pixel centre."""
        dx, dy = self.x_mm - centre[0], self.y_mm - centre[1]
        if shape == "cylinder":
            inside = np.hypot(dx, dy) <= size_mm[0] / 2
        else:
            inside = (np.abs(dx) <= size_mm[0] / 2) & (np.abs(dy) <= size_mm[1] / 2)
        if inside.any():
            return inside / inside.sum()
        hat = np.clip(1.0 - np.abs(dx) / self.pixel_mm, 0, None) * np.clip(1.0 - np.abs(dy) / self.pixel_mm, 0, None)
        if not hat.any():
            raise ValueError(f"a magnet at ({centre[0]:g}, {centre[1]:g}) mm lies outside the pad grid")
        return hat / hat.sum()

    def _magnets_field_ut(self, centres: np.ndarray, omega: np.ndarray) -> np.ndarray:
        rotations = rotation_matrix(omega)
        field = np.zeros((len(self.chips_mm), 3))
        for m, centre, j, rot in zip(self.body.magnets, centres, self._polarisations, rotations):
            # magnets are axis-aligned at rest, so their own frame is the pad's and J is given in it
            field += magnet_field_t(self.chips_mm, shape=m.shape, size_mm=m.size_mm, polarisation_t=j,
                                    centre_mm=centre, rotation=rot)
        return field * _TESLA_TO_UT



def _overlap(centres_mm: np.ndarray, pixel_mm: float, n_cells: int, cell_mm: float) -> np.ndarray:
    """(n_cells, n_pixels) share of each pixel (centres ascending) in each of ``n_cells`` centred cells along one
    axis; the end cells reach to infinity, so every pixel's shares sum to 1 (force is conserved)."""
    edges = (np.arange(n_cells + 1) - n_cells / 2.0) * cell_mm
    edges[0], edges[-1] = -np.inf, np.inf
    lo, hi = centres_mm - pixel_mm / 2.0, centres_mm + pixel_mm / 2.0
    width = np.minimum(hi[None, :], edges[1:, None]) - np.maximum(lo[None, :], edges[:-1, None])
    return np.clip(width, 0.0, None) / pixel_mm
