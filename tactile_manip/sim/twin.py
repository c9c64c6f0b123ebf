"""A board's twin: the reading at a probe rig's logged pose, from a press kernel and the magnets' closed-form field.

The full press (:mod:`tactile_manip.sim.board_press`: a contact solve, then the layer's displacement by FFT) takes
tens of milliseconds; a fit to a few thousand logged presses needs the reading at every row many hundreds of times.
The twin therefore replaces the layer's solution by its far field: a press of approach ``d`` at ``p`` on the pad
moves a magnet whose centre lies ``h`` below the surface at in-plane offset ``r`` as Boussinesq's point load on an
incompressible half-space (Poisson ratio 1/2) does,

    u_z = -s (1 + h^2 / R^2) / R,    u_r = a_r s r h / R^3,    R = sqrt(r^2 + h^2),    s = A d^n,

(``s = P / (4 pi G)``, a length squared: the press's force over the shear modulus), with ``h`` a fitted kernel
depth (the layer is bonded to a rigid base and the probe is no point, so the depth that fits is not the magnet's
own), ``a_r`` a lateral scale (the printed lattice is not an isotropic solid) and the magnet turning by
``a_w`` times the exact rotation of ``curl(u) / 2``. Each magnet's field is then the closed form of its disc at
the moved and turned pose (:func:`~tactile_manip.sim.magnets.cylinder_field_t`), not linearised. A chip reads
``M_c B + o_c``: ``M_c`` is the fitted 3x3 readout of chip ``c`` (its turn, gain and misalignment; default the
board file's axis map) and ``o_c`` its offset (rest field only).

The probe's stage pose maps onto the pad by the rig frame: ``p = R(turn) S (xy_stage - origin)`` (``S`` mirrors
y on a left-handed rig) and
``d = (z_stage - contact_z) * depth_per_z`` (``depth_per_z = -1``: a smaller stage z is a deeper press), clipped at
0. A skin that softens over a run scales ``s`` by ``1 + softening_per_hour * t_h``.

Two terms describe the printed skin better than a half-space, each off unless fitted:

- the base: the layer is bonded to a rigid base (the chips' board) ``T`` below the surface, which the half-space
  kernel ignores; the press's image in that base (a point load of ``-base_image`` times the press, at depth
  ``h + 2 (T - depth of the magnet)`` below the magnet) takes out the motion a base does not allow far from the
  press;
- the cells: the eFlesh skin is a printed cut-cell lattice (TPU), not a solid. A press on one of its nodes loads the
  struts under it, one between nodes the cell's face, so how the press moves the magnets depends on where it lands
  in a cell. The lattice is a square of pitch ``cell_period_mm`` turned ``cell_angle_deg`` on the pad, its nodes at
  ``cell_phase`` periods along its axes; a press's closeness to a node is
  ``g = ((1 + cos a1) (1 + cos a2) / 4)^cell_sharpness`` (``a_i`` its phase along axis i, rad; 1 on a node, 0 midway
  between rows), and on a node the strength, the kernel depth and the tilt scale are multiplied by
  ``exp(cell_stiffness g)``, ``exp(cell_depth g)`` and ``exp(cell_tilt g)``.

Lengths mm, fields uT in pad axes (``*_pad_ut``) or chip axes, firmware order. numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tactile_manip.boards.load import Board
from tactile_manip.boards.spec import TwinSpec
from tactile_manip.checks import check_array
from tactile_manip.errors import ConfigError
from tactile_manip.sim.magnets import cylinder_field_t

_TESLA_TO_UT = 1e6
_CURL_STEP_MM = 0.05  # central differences of the kernel for its curl


@dataclass(frozen=True)
class Magnets:
    """Discs as arrays: (M, 3) centres (mm, pad frame), (M,) signed polarisation along +z (T), (M, 2) size
    (diameter, height, mm)."""

    centres_mm: np.ndarray
    polarisation_t: np.ndarray
    size_mm: np.ndarray


def board_magnets(board: Board) -> Magnets:
    """The board file's discs (body kind "magnets", cylinders only) as :class:`Magnets`."""
    board.require_simulation()
    body = board.body
    assert body is not None
    if body.kind != "magnets" or any(m.shape != "cylinder" for m in body.magnets):
        raise ConfigError(f"board {board.name}: the twin describes disc magnets ([[body.magnets]] with shape "
                          "\"cylinder\"); a magnetised layer or cuboids are simulated by `simulate` only")
    return Magnets(centres_mm=np.array([m.position_mm for m in body.magnets], float),
                   polarisation_t=np.array([m.polarisation_t[2] for m in body.magnets], float),
                   size_mm=np.array([m.size_mm for m in body.magnets], float))


def rig_to_pad(stage_xyz_mm: np.ndarray, *, origin_mm: tuple[float, float], turn_deg: float, contact_z_mm: float,
               depth_per_z: float, mirror: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) stage poses -> (N, 2) probe point in the pad frame (mm) and (N,) approach past first touch (mm, >= 0):
    ``p = R(turn) S (xy - origin)``, ``S`` mirroring y where ``mirror``."""
    a = math.radians(turn_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    if mirror:
        rot = rot @ np.diag([1.0, -1.0])
    xy = (stage_xyz_mm[:, :2] - np.asarray(origin_mm)) @ rot.T
    return xy, np.maximum((stage_xyz_mm[:, 2] - contact_z_mm) * depth_per_z, 0.0)


def kernel_displacement(dx: np.ndarray, dy: np.ndarray, depth_mm: np.ndarray, strength: np.ndarray,
                        lateral_scale: float) -> np.ndarray:
    """(..., 3) displacement (mm, pad axes, z outward) at in-plane offset (dx, dy) from the press and ``depth_mm``
    below the surface, for a press of ``strength`` s = P / (4 pi G) (mm^2); see the module docstring."""
    r_sq = dx * dx + dy * dy
    big_r = np.sqrt(r_sq + depth_mm * depth_mm)
    u_z = -strength * (1.0 + depth_mm * depth_mm / big_r ** 2) / big_r
    u_r = lateral_scale * strength * depth_mm / big_r ** 3
    return np.stack([u_r * dx, u_r * dy, u_z], axis=-1)


@dataclass(frozen=True)
class Cells:
    """The printed lattice's nodes and what a press on one changes (see the module docstring): pitch (mm), turn
    (deg), a node's phase along each axis (periods), sharpness, and the logs of the factors on strength, kernel depth
    and tilt scale."""

    period_mm: float
    angle_deg: float = 0.0
    phase: tuple[float, float] = (0.0, 0.0)
    sharpness: float = 1.0
    stiffness: float = 0.0
    depth: float = 0.0
    tilt: float = 0.0

    @classmethod
    def of(cls, twin: TwinSpec) -> Cells | None:
        """The ``[twin]`` table's lattice term, or None where it has none (``cell_period_mm`` 0)."""
        if twin.cell_period_mm <= 0.0:
            return None
        phase = (float(twin.cell_phase[0]), float(twin.cell_phase[1]))
        return cls(twin.cell_period_mm, twin.cell_angle_deg, phase, twin.cell_sharpness, twin.cell_stiffness,
                   twin.cell_depth, twin.cell_tilt)


def node_closeness(probe_xy_mm: np.ndarray, cells: Cells) -> np.ndarray:
    """(N,) how close each of (N, 2) pad points (mm) lies to a node of the lattice: 1 on a node, 0 midway between
    two rows of nodes."""
    a = math.radians(cells.angle_deg)
    along = probe_xy_mm @ np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])  # lattice axes
    phase = 2.0 * np.pi * (along / cells.period_mm - np.asarray(cells.phase))
    return (0.25 * (1.0 + np.cos(phase[:, 0])) * (1.0 + np.cos(phase[:, 1]))) ** cells.sharpness


def magnet_motion(probe_xy_mm: np.ndarray, strength: np.ndarray, centres_mm: np.ndarray, *,
                  kernel_depth_mm: float | np.ndarray, lateral_scale: float,
                  tilt_scale: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each magnet's displacement (N, M, 3) mm and rotation vector (N, M, 3) rad under N presses at (N, 2) points
    of (N,) strengths; the kernel depth a number or one per press (N,) or per press and magnet (N, M), the tilt
    scale a number or one per press (N,)."""
    dx = centres_mm[None, :, 0] - probe_xy_mm[:, None, 0]
    dy = centres_mm[None, :, 1] - probe_xy_mm[:, None, 1]
    h = np.asarray(kernel_depth_mm, float)
    h = np.broadcast_to(h[:, None] if h.ndim == 1 else h, dx.shape).copy()
    s = strength[:, None]
    u = kernel_displacement(dx, dy, h, s, lateral_scale)
    tilt = np.asarray(tilt_scale, float)
    if not np.any(tilt):
        return u, np.zeros_like(u)
    e = _CURL_STEP_MM
    grad = np.empty(u.shape + (3,))  # [..., i, j] = d u_i / d x_j; pad z is minus the depth
    for j, (ex, ey, eh) in enumerate(((e, 0.0, 0.0), (0.0, e, 0.0), (0.0, 0.0, -e))):
        grad[..., j] = (kernel_displacement(dx + ex, dy + ey, h + eh, s, lateral_scale)
                        - kernel_displacement(dx - ex, dy - ey, h - eh, s, lateral_scale)) / (2 * e)
    omega = 0.5 * np.stack([grad[..., 2, 1] - grad[..., 1, 2], grad[..., 0, 2] - grad[..., 2, 0],
                            grad[..., 1, 0] - grad[..., 0, 1]], axis=-1)
    return u, (tilt[:, None, None] if tilt.ndim == 1 else tilt) * omega


def rotations(omega: np.ndarray) -> np.ndarray:
    """(..., 3, 3) exact rotations (Rodrigues) of rotation vectors (..., 3), rad."""
    angle = np.linalg.norm(omega, axis=-1)[..., None, None]
    k = omega / np.maximum(np.linalg.norm(omega, axis=-1, keepdims=True), 1e-15)
    cross = np.zeros(omega.shape[:-1] + (3, 3))
    cross[..., 0, 1], cross[..., 0, 2], cross[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    cross[..., 1, 0], cross[..., 2, 0], cross[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    return np.eye(3) + np.sin(angle) * cross + (1.0 - np.cos(angle)) * cross @ cross


def discs_field_pad_ut(chips_mm: np.ndarray, magnets: Magnets, centres_mm: np.ndarray,
                       rotation: np.ndarray | None = None) -> np.ndarray:
    """(N, C, 3) field (uT, pad axes) at (C, 3) chips of the discs at (N, M, 3) centres, turned by (N, M, 3, 3)
    rotations (None: axis-aligned)."""
    n, m = centres_mm.shape[:2]
    out = np.zeros((n, len(chips_mm), 3))
    for i in range(m):
        rel = chips_mm[None] - centres_mm[:, i, None, :]                       # (N, C, 3) pad frame
        local = rel if rotation is None else np.einsum("ncj,nji->nci", rel, rotation[:, i])  # R^T (p - c)
        b = cylinder_field_t(local.reshape(-1, 3), diameter_mm=magnets.size_mm[i, 0],
                             height_mm=magnets.size_mm[i, 1], polarisation_t=magnets.polarisation_t[i])
        b = b.reshape(n, -1, 3)
        out += b if rotation is None else np.einsum("nij,ncj->nci", rotation[:, i], b)
    return out * _TESLA_TO_UT


def press_change_pad_ut(chips_mm: np.ndarray, magnets: Magnets, probe_xy_mm: np.ndarray, strength: np.ndarray, *,
                        kernel_depth_mm: float, lateral_scale: float, tilt_scale: float, base_image: float = 0.0,
                        base_depth_mm: float = 0.0, cells: Cells | None = None) -> np.ndarray:
    """(N, C, 3) field change (uT, pad axes) at the chips under N presses (see :func:`magnet_motion`), with the
    press's image in a rigid base ``base_depth_mm`` below the surface (share ``base_image``; 0: none) and the
    lattice's nodes (``cells``; None: none), as the module docstring says."""
    n = len(probe_xy_mm)
    depth, tilt = np.full(n, float(kernel_depth_mm)), np.full(n, float(tilt_scale))
    if cells is not None:
        g = node_closeness(probe_xy_mm, cells)
        strength = strength * np.exp(cells.stiffness * g)
        depth, tilt = depth * np.exp(cells.depth * g), tilt * np.exp(cells.tilt * g)
    u, omega = magnet_motion(probe_xy_mm, strength, magnets.centres_mm, kernel_depth_mm=depth,
                             lateral_scale=lateral_scale, tilt_scale=tilt)
    if base_image > 0.0:
        image = depth[:, None] + 2.0 * np.maximum(base_depth_mm + magnets.centres_mm[None, :, 2], 0.0)
        u_image, omega_image = magnet_motion(probe_xy_mm, base_image * strength, magnets.centres_mm,
                                             kernel_depth_mm=image, lateral_scale=lateral_scale, tilt_scale=tilt)
        u, omega = u - u_image, omega - omega_image
    rest = discs_field_pad_ut(chips_mm, magnets, magnets.centres_mm[None])
    moved = discs_field_pad_ut(chips_mm, magnets, magnets.centres_mm[None] + u,
                               None if not np.any(tilt) else rotations(omega))
    return moved - rest


class BoardTwin:
    """The twin of a fitted board file (one with a ``[twin]`` table, written by ``tactile-manip fit-board``).

    Args:
        board: a simulatable board with disc magnets and a ``[twin]`` table.

    Raises:
        ConfigError: the board has no ``[twin]`` table, or is not one the twin can simulate.
    """

    def __init__(self, board: Board) -> None:
        if board.twin is None:
            raise ConfigError(f"board {board.name} has no [twin] table: fit one to your logs with "
                              "`tactile-manip fit-board` (docs/your_board.md)")
        self.board, self.spec = board, board.twin
        self.magnets = board_magnets(board)
        self.chips_mm = board.chip_positions_mm()
        self.readout, self.offset_ut = readout_arrays(board, board.twin)

    def change_pad_ut(self, stage_xyz_mm: np.ndarray, time_h: np.ndarray | None = None) -> np.ndarray:
        """(N, C, 3) field change (uT, pad axes) at logged stage poses (N, 3) mm, ``time_h`` hours into the run."""
        xy, approach = self.pad_poses(stage_xyz_mm)
        return self.change_at_pad_ut(xy, approach, time_h)

    def pad_poses(self, stage_xyz_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) stage poses (mm) -> (N, 2) press points in the pad frame (mm) and (N,) approaches (mm, >= 0)."""
        stage = check_array("stage_xyz_mm", stage_xyz_mm, shape=(None, 3))
        t = self.spec
        return rig_to_pad(stage, origin_mm=t.rig_origin_mm, turn_deg=t.rig_turn_deg, contact_z_mm=t.contact_z_mm,
                          depth_per_z=t.depth_per_z, mirror=t.rig_mirror)

    def change_at_pad_ut(self, probe_xy_mm: np.ndarray, approach_mm: np.ndarray,
                         time_h: np.ndarray | None = None) -> np.ndarray:
        """(N, C, 3) field change (uT, pad axes) under presses at (N, 2) pad points (mm) of (N,) approaches (mm):
        presses anywhere on the pad, without a rig (simulated presses to train a contact model on, say)."""
        xy = check_array("probe_xy_mm", probe_xy_mm, shape=(None, 2))
        approach = np.maximum(check_array("approach_mm", approach_mm, shape=(len(xy),)), 0.0)
        t = self.spec
        return press_change_pad_ut(self.chips_mm, self.magnets, xy, press_strength(approach, t, time_h),
                                   kernel_depth_mm=t.kernel_depth_mm, lateral_scale=t.lateral_scale,
                                   tilt_scale=t.tilt_scale, base_image=t.base_image,
                                   base_depth_mm=self.board.layer.thickness_mm,  # type: ignore[union-attr]
                                   cells=Cells.of(t))

    def readings_ut(self, stage_xyz_mm: np.ndarray, time_h: np.ndarray | None = None, *,
                    raw: bool = False) -> np.ndarray:
        """(N, C, 3) chip-axes readings (uT, firmware order) at logged stage poses: baseline-subtracted, or with
        ``raw`` the rest field and offsets added (what the chips stream)."""
        return self._read(self.change_pad_ut(stage_xyz_mm, time_h), raw)

    def readings_at_pad_ut(self, probe_xy_mm: np.ndarray, approach_mm: np.ndarray,
                           time_h: np.ndarray | None = None, *, raw: bool = False) -> np.ndarray:
        """(N, C, 3) chip-axes readings (uT) under presses at pad points (see :meth:`change_at_pad_ut`)."""
        return self._read(self.change_at_pad_ut(probe_xy_mm, approach_mm, time_h), raw)

    def _read(self, change_pad_ut: np.ndarray, raw: bool) -> np.ndarray:
        out = np.einsum("cij,ncj->nci", self.readout, change_pad_ut)
        return out + self.rest_readings_ut() if raw else out

    def rest_readings_ut(self) -> np.ndarray:
        """(C, 3) the untouched board's raw reading, chip axes, uT."""
        rest = discs_field_pad_ut(self.chips_mm, self.magnets, self.magnets.centres_mm[None])[0]
        return np.einsum("cij,cj->ci", self.readout, rest) + self.offset_ut


def stage_grid(board: Board, *, step_mm: float = 0.5, margin_mm: float = -4.0, depth_mm: float = 6.0,
               depths: int = 12) -> np.ndarray:
    """(G, 3) stage poses (x, y, z mm) that press a fitted board's pad all over: its layer less ``margin_mm`` (less
    than nothing: a little beyond it, since a rig frame fitted on a few labels may sit millimetres off) in steps of
    ``step_mm``, ``depths`` approaches evenly up to ``depth_mm``, taken to the stage by the board's ``[twin]`` rig
    frame (a twin fitted without labels has the pad's own: its centre, no turn). Raises ``ConfigError`` for a board
    without a ``[twin]`` table or a grid of no point."""
    twin = board.twin
    if twin is None:
        raise ConfigError(f"board {board.name} has no [twin] table: fit one to your logs with `tactile-manip "
                          "fit-board` (docs/your_board.md)")
    if not (step_mm > 0 and depth_mm > 0 and depths >= 1):
        raise ConfigError(f"a grid of stage poses needs a positive step ({step_mm} mm) and depth ({depth_mm} mm) and "
                          f"one approach or more ({depths})")
    half = np.array(board.layer.size_mm) / 2 - margin_mm
    if (half <= 0).any():
        raise ConfigError(f"a margin of {margin_mm} mm leaves nothing of board {board.name}'s "
                          f"{board.layer.size_mm[0]:g} x {board.layer.size_mm[1]:g} mm layer")
    gx, gy = (np.arange(-h, h + step_mm / 2, step_mm) for h in half)
    pad = np.stack(np.meshgrid(gx, gy, indexing="ij"), axis=-1).reshape(-1, 2)
    turn = np.radians(twin.rig_turn_deg)
    back = np.array([[np.cos(turn), np.sin(turn)], [-np.sin(turn), np.cos(turn)]])  # R(-turn)
    xy = pad @ back.T
    if twin.rig_mirror:
        xy[:, 1] = -xy[:, 1]
    xy += np.asarray(twin.rig_origin_mm)
    z = twin.contact_z_mm + np.linspace(depth_mm / depths, depth_mm, depths) / twin.depth_per_z
    return np.c_[np.repeat(xy, depths, axis=0), np.tile(z, len(xy))]


def press_strength(approach_mm: np.ndarray, twin: TwinSpec, time_h: np.ndarray | None = None) -> np.ndarray:
    """(N,) s = A d^n (mm^2), softened by ``1 + softening_per_hour * t_h`` where times are given."""
    s = twin.press_gain * np.power(approach_mm, twin.press_exponent)
    if time_h is not None and twin.softening_per_hour:
        s = s * (1.0 + twin.softening_per_hour * np.asarray(time_h, float))
    return s


def readout_arrays(board: Board, twin: TwinSpec | None) -> tuple[np.ndarray, np.ndarray]:
    """(C, 3, 3) pad field -> chip reading and (C, 3) offsets (uT): the twin's fitted readout, or the board file's
    axis maps (transposed) and no offset."""
    if twin is None or not twin.readout:
        return np.transpose(board.chip_matrices(), (0, 2, 1)), np.zeros((board.n_chips, 3))
    if len(twin.readout) != board.n_chips:
        raise ConfigError(f"board {board.name}: [[twin.readout]] has {len(twin.readout)} entries for "
                          f"{board.n_chips} chips; give one per chip, in firmware order")
    return (np.array([r.matrix for r in twin.readout], float), np.array([r.offset_ut for r in twin.readout], float))
