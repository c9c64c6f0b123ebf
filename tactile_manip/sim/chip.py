"""A board's magnetometers under the skin: Earth field, misalignment, noise and quantisation.

Fields here are microtesla (``_ut``), one row per chip in the board's firmware order: ``(n_chips, 3)`` arrays
in the pad's axes (the board maps them onto its reading grid, :meth:`~tactile_manip.boards.Board.cells_from_pad`).
The chain from the magnet's field at the chips (pad axes) to a register value is

    field + Earth  ->  rotate by the chip's misalignment  ->  + drift + noise  ->  round(/ LSB)  ->  clip.

The chips measure along the pad's axes (their mounting turn on the board is the driver's business): the
quantisation is the same for turns by right angles, which every shipped board has.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile_manip.boards import Board
from tactile_manip.checks import check_array, check_finite_scalar
from tactile_manip.sim.params import ChipParams

_INT16_MAX = 32767


def chip_positions_mm(board: Board, *, thickness_mm: float, gap_mm: float) -> np.ndarray:
    """The board's chip sensing points in the pad frame, mm: (n_chips, 3) ``x, y, z``, firmware order.

    ``x, y`` are the board file's; ``z = -(thickness + gap)``, below a layer of ``thickness_mm`` with the chips
    ``gap_mm`` under its base (the simulator's gap may differ from the file's: it is randomised).
    """
    thick = check_finite_scalar("thickness_mm", thickness_mm, low=0.0, low_open=True)
    gap = check_finite_scalar("gap_mm", gap_mm, low=0.0, low_open=True)
    pos = np.empty((board.n_chips, 3))
    pos[:, :2] = [c.position_mm for c in board.chips]
    pos[:, 2] = -(thick + gap)
    return pos


def _rotations(axes: np.ndarray, angles_rad: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from unit axes (..., 3) and angles (...,) by Rodrigues' formula."""
    k = np.zeros(axes.shape + (3,))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axes[..., 2], axes[..., 1], -axes[..., 0]
    k -= np.swapaxes(k, -1, -2)  # fill the lower triangle: K is skew-symmetric
    s, c = np.sin(angles_rad)[..., None, None], np.cos(angles_rad)[..., None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def _unit_vectors(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Directions uniform on the sphere, (*shape, 3)."""
    v = rng.standard_normal(shape + (3,))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True, eq=False)
class Measurement:
    """One frame of the array as the chips report it.

    Attributes:
        counts: (n_chips, 3) int16 register values, LSB.
        raw_ut: (n_chips, 3) float32 ``counts * LSB``, uT (not baseline-subtracted).
        saturated: (n_chips, 3) bool, True where the count hit the rail ``+-saturation_counts``.
    """

    counts: np.ndarray
    raw_ut: np.ndarray
    saturated: np.ndarray


@dataclass(eq=False)
class ChipArray:
    """Per-sensor constants drawn once: Earth field and the mounting rotation of each chip.

    Attributes:
        params: the chip parameters (LSB, noise, saturation, ...).
        earth_ut: (3,) Earth field in pad axes, uT; random direction, magnitude ``params.earth_field_ut``.
        rotations: (n_chips, 3, 3) rotation of each chip: its columns are the chip's axes in pad axes, so a
            pad-frame field ``b`` reads ``R.T @ b``. Random axis, angle ~ N(0, ``params.rotation_deg``)
            (that is the RMS angle); exactly the identity when ``rotation_deg`` is 0.
    """

    params: ChipParams
    earth_ut: np.ndarray
    rotations: np.ndarray

    def __post_init__(self) -> None:
        self.earth_ut = check_array("earth_ut", self.earth_ut, shape=(3,))
        self.rotations = check_array("rotations", self.rotations, shape=None)
        if self.rotations.ndim != 3 or self.rotations.shape[1:] != (3, 3):
            raise ValueError(f"rotations: expected shape (n_chips, 3, 3), got {self.rotations.shape}")
        self._shape = (self.rotations.shape[0], 3)
        if self.params.saturation_counts > _INT16_MAX:
            raise ValueError(f"params.saturation_counts must be <= {_INT16_MAX} (int16 register), got "
                             f"{self.params.saturation_counts}")
        self._lsb_ut = np.array([self.params.lsb_xy_ut, self.params.lsb_xy_ut, self.params.lsb_z_ut])
        self._noise_ut = np.array([self.params.noise_xy_ut, self.params.noise_xy_ut, self.params.noise_z_ut])

    @property
    def n_chips(self) -> int:
        return self._shape[0]

    @classmethod
    def create(cls, params: ChipParams, rng: np.random.Generator, *, n_chips: int) -> ChipArray:
        """Draw the Earth field direction and the rotations of ``n_chips`` chips from ``rng``."""
        earth = _unit_vectors(rng, ()) * params.earth_field_ut
        axes = _unit_vectors(rng, (n_chips,))
        angles = rng.standard_normal((n_chips,)) * np.deg2rad(params.rotation_deg)
        return cls(params=params, earth_ut=earth, rotations=_rotations(axes, angles))

    def expected_ut(self, field_ut: object) -> np.ndarray:
        """Noise-free, drift-free reading (n_chips, 3) in uT, not quantised: the idle-frame average (baseline).

        Args:
            field_ut: (n_chips, 3) magnet field at the chips in pad axes, uT (float32 or float64).

        Returns:
            (n_chips, 3) float64 ``R.T @ (field + earth)`` per chip, uT in chip axes.
        """
        b = check_array("field_ut", field_ut, shape=self._shape) + self.earth_ut
        return np.einsum("nji,nj->ni", self.rotations, b)

    def measure(self, field_ut: object, rng: np.random.Generator, *, drift_ut: object | None = None
                ) -> Measurement:
        """One frame: expected reading + drift + Gaussian noise, rounded to counts and clipped to the rail.

        Args:
            field_ut: (n_chips, 3) magnet field at the chips in pad axes, uT; NaN or inf raises ValueError.
            rng: source of the noise (always draws one (n_chips, 3) standard normal array).
            drift_ut: optional (n_chips, 3) offset in chip axes, uT, from :meth:`draw_drift` (once per press).

        Returns:
            The :class:`Measurement`; ``saturated`` marks counts at ``+-params.saturation_counts``.
        """
        value = self.expected_ut(field_ut)
        if drift_ut is not None:
            value = value + check_array("drift_ut", drift_ut, shape=self._shape)
        value = value + rng.standard_normal(self._shape) * self._noise_ut
        rail = self.params.saturation_counts
        counts = np.clip(np.rint(value / self._lsb_ut), -rail, rail).astype(np.int16)
        saturated = np.abs(counts.astype(np.int32)) >= rail
        return Measurement(counts=counts, raw_ut=self.counts_to_ut(counts), saturated=saturated)

    def draw_drift(self, rng: np.random.Generator) -> np.ndarray:
        """A per-press offset (n_chips, 3) in uT, each entry ~ N(0, ``params.drift_ut``)."""
        return rng.standard_normal(self._shape) * self.params.drift_ut

    def counts_to_ut(self, counts: object) -> np.ndarray:
        """Register values (..., 3) in LSB to float32 uT (x, y at ``lsb_xy_ut``, z at ``lsb_z_ut``)."""
        c = check_array("counts", counts, shape=None)
        if c.ndim == 0 or c.shape[-1] != 3:
            raise ValueError(f"counts: expected shape (..., 3), got {c.shape}")
        return (c * self._lsb_ut).astype(np.float32)
