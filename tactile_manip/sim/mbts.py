"""Magnetic field of the deformed skin at the magnetometers.

The skin (uniform polarisation ``J_r`` along the pad normal) is split into dipole cells
(:func:`~tactile_manip.sim.magnetics.skin_cells`). Under a contact pressure each cell moves with the
layer's internal displacement ``u`` and its moment follows the local deformation: rotated by the exact
rotation of ``omega = curl(u) / 2`` (``transport = "rotation"``) or mapped by the deformation gradient
``F = I + grad u`` (``"affine"``). The field change at the chips is the dipole sum of the deformed skin
minus that of the undeformed skin; the no-contact field is the exact closed form of the cuboid, so the
discretisation error enters only the (small) change.

This is the skin model of a board whose body is a square magnetised layer (the SuperMag pad); any other
described board (a rectangular layer, discrete magnets) is :class:`~tactile_manip.sim.board_skin.BoardSkin`.
Both give fields at the board's chips, firmware order, pad axes: ``(n_chips, 3)``.
"""

from __future__ import annotations

import numpy as np

from tactile_manip.boards import Board
from tactile_manip.sim.chip import chip_positions_mm
from tactile_manip.sim.deformation import layer_fields, rotate, rotation_vectors
from tactile_manip.sim.magnetics import cuboid_field_t, dipole_field_t, skin_cells, skin_dipoles
from tactile_manip.sim.params import LayerParams, MagnetParams


def is_square_layer(board: Board) -> bool:
    """Whether ``board``'s body is a magnetised layer on a square pad (what :class:`MagneticSkin` models)."""
    return (board.body is not None and board.body.kind == "layer" and board.layer is not None
            and board.layer.size_mm[0] == board.layer.size_mm[1])


class MagneticSkin:
    """A square magnetised skin over a board's chips: baseline field and field change under a pressure.

    Construction precomputes the undeformed dipoles and fields (a few ms); it does no I/O.

    Args:
        board: a board whose body is a square magnetised layer (:func:`is_square_layer`): its chips and layer.
        layer: the skin's modulus (``skin_modulus_kpa``, filled in from the board or drawn).
        magnet: the remanence, the chips' gap and the dipole cells (filled in from the board or drawn).
    """

    def __init__(self, board: Board, layer: LayerParams, magnet: MagnetParams) -> None:
        if not is_square_layer(board):
            raise ValueError(f"board {board.name}: MagneticSkin models a square magnetised layer; use BoardSkin")
        self.board, self.layer, self.magnet = board, layer, magnet
        self.size_mm, self.thickness_mm = board.layer.size_mm[0], board.layer.thickness_mm
        self.cells = skin_cells(size_mm=self.size_mm, thickness_mm=self.thickness_mm,
                                cell_mm=magnet.cell_mm, nodes=magnet.thickness_nodes)
        self.chips_mm = chip_positions_mm(board, thickness_mm=self.thickness_mm, gap_mm=magnet.chip_gap_mm)
        self.polarisation_t = np.array([0.0, 0.0, magnet.remanence_t])
        self._positions, self._moments = skin_dipoles(self.cells, self.polarisation_t)
        self._rest_t = dipole_field_t(self.chips_mm, self._positions, self._moments)
        ny, nx, _ = self.cells.xy_mm.shape
        self._grid_shape = (ny, nx, self.cells.z_mm.size)

    def baseline_t(self) -> np.ndarray:
        """(n_chips, 3) field of the undeformed skin at the chips, tesla (exact cuboid closed form)."""
        size = (self.size_mm, self.size_mm, self.thickness_mm)
        return cuboid_field_t(self.chips_mm, size_mm=size, centre_mm=(0.0, 0.0, -self.thickness_mm / 2),
                              polarisation_t=self.polarisation_t)

    def rest_field_ut(self) -> np.ndarray:
        """(n_chips, 3) field of the undeformed skin at the chips, pad axes, uT."""
        return self.baseline_t() * 1e6

    def contact_change_ut(self, pressure_mpa: np.ndarray, pixel_mm: float) -> np.ndarray:
        """(n_chips, 3) change of the field at the chips (pad axes, uT) under a pressure on the pad."""
        return self.field_change_t(pressure_mpa, pixel_mm) * 1e6

    def field_change_t(self, pressure_mpa: np.ndarray, pixel_mm: float) -> np.ndarray:
        """(n_chips, 3) change of the field at the chips (tesla) under a pressure on the pad.

        Args:
            pressure_mpa: (n, n) pressure on a grid of ``pixel_mm`` cells covering the pad, MPa.
            pixel_mm: that grid's spacing, mm.
        """
        cell_pressure = self._bin_to_cells(pressure_mpa, pixel_mm)
        if not cell_pressure.any():
            return np.zeros((len(self.chips_mm), 3))
        u, grad = layer_fields(cell_pressure, cell_mm=self.cells.cell_mm, z_mm=self.cells.z_mm,
                               thickness_mm=self.thickness_mm,
                               modulus_mpa=self.layer.skin_modulus_kpa * 1e-3)
        # (nz, ny, nx, ...) -> (ny, nx, nz, ...) to match the dipole ordering
        u = np.moveaxis(u, 0, 2).reshape(-1, 3)
        grad = np.moveaxis(grad, 0, 2).reshape(-1, 3, 3)
        moments = self._moved_moments(grad)
        deformed = dipole_field_t(self.chips_mm, self._positions + u, moments)
        return deformed - self._rest_t

    def _moved_moments(self, grad: np.ndarray) -> np.ndarray:
        if self.magnet.transport == "rotation":
            return rotate(self._moments, rotation_vectors(grad))
        return self._moments + np.einsum("mij,mj->mi", grad, self._moments)

    def _bin_to_cells(self, pressure_mpa: np.ndarray, pixel_mm: float) -> np.ndarray:
        """Force-conserving transfer of a pad pressure grid onto the dipole cell grid (MPa)."""
        n = pressure_mpa.shape[0]
        ny, nx, _ = self._grid_shape
        # Both grids share the pad's (-x, +y) corner as origin, so rows and columns map alike.
        index = ((np.arange(n) + 0.5) * pixel_mm // self.cells.cell_mm).astype(int)
        row = np.clip(index, 0, ny - 1)
        col = np.clip(index, 0, nx - 1)
        force = pressure_mpa * pixel_mm**2
        flat = (row[:, None] * nx + col[None, :]).ravel()
        binned = np.bincount(flat, weights=force.ravel(), minlength=ny * nx).reshape(ny, nx)
        return binned / self.cells.cell_mm**2
