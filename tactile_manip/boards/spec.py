"""What a board file describes: the chips of a magnetic skin's board, its wire format, and, for simulation, its
magnetic body and compliant layer.

These dataclasses mirror the tables of a board file (``tactile_manip/boards/*.toml``; docs/your_board.md):

- ``[board]``: name, reading grid, pitch, where the figures come from;
- ``[[chips]]`` (or ``[chip_grid]``): each chip in the order its firmware sends them, with its reading cell,
  its position in the pad frame (mm) and the map of its axes onto the pad's;
- ``[chip]``: the magnetometer's LSB sizes, output rail and rate (:class:`~tactile_manip.chips.ChipModelSpec`);
- ``[wire]``: the wire format of the serial backend and the baud rate;
- ``[body]``: the magnetic body, a magnetised layer or discrete magnets (``[[body.magnets]]``, cylinders
  and cuboids), optional;
- ``[layer]``: the compliant layer (size, thickness, Young's modulus, and the gap from its base down to the
  chips' sensing plane), optional;
- ``[twin]``: a board fitted to its owner's logs (``tactile-manip fit-board``): the probe rig's frame, the press
  kernel and each chip's 3x3 readout (:mod:`tactile_manip.sim.twin`), optional;
- ``[fit]``: what the fit saw and how well it fits (file hashes, rows, residuals), free-form, optional.

A board without ``[body]`` and ``[layer]`` can import, train and evaluate, but not be simulated. The pad frame is
that of docs/design.md: origin at the centre of the undeformed top surface, z along the outward normal, so
the compliant layer fills ``z in [-thickness, 0]`` and the chips sit at ``z = -(thickness + gap)``.

numpy only, like every core module.
"""

from __future__ import annotations

import math
import unicodedata
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from tactile_manip.chips import ChipModelSpec
from tactile_manip.wire import WIRE_FORMATS

# the pad axis each signed name stands for (a chip's axis map is three of these)
AXIS_VECTORS: dict[str, tuple[float, float, float]] = {
    "+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0), "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0),
}
MAX_CHIPS = 1024  # more chips than any magnetic-skin board carries: a bigger count is a typing error


def _finite(where: str, value: float, *, low: float | None = None, high: float | None = None,
            low_open: bool = True) -> None:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise ValueError(f"{where} must be a finite number, got {value!r}")
    if low is not None and (value <= low if low_open else value < low):
        raise ValueError(f"{where} must be {'>' if low_open else '>='} {low}, got {value}")
    if high is not None and value > high:
        raise ValueError(f"{where} must be <= {high}, got {value}")


def axis_matrix(axes: tuple[str, str, str]) -> np.ndarray:
    """The (3, 3) matrix that takes a field in a chip's axes to the pad's: column i is the pad direction the
    chip's i-th axis points along (``("-y", "+x", "+z")``: chip x along pad -y, chip y along pad +x).

    Raises:
        ValueError: a name that is not one of ``+x -x +y -y +z -z``, or three that are not orthogonal.
    """
    unknown = [a for a in axes if a not in AXIS_VECTORS]
    if unknown or len(axes) != 3:
        raise ValueError(f"axes must be three of {', '.join(AXIS_VECTORS)}, got {list(axes)}")
    matrix = np.array([AXIS_VECTORS[a] for a in axes]).T
    if abs(abs(np.linalg.det(matrix)) - 1.0) > 1e-9:
        raise ValueError(f"axes {list(axes)} name one pad axis twice; each chip axis needs its own")
    return matrix


@dataclass(frozen=True)
class ChipSpec:
    """One chip, in the order the board's firmware sends them.

    ``axes`` maps the chip's axes onto the pad's (see :func:`axis_matrix`); ``rotation_deg`` is the other way to
    say an in-plane turn (counter-clockwise, chip axes to pad axes, any angle). Give at most one of them.
    """

    cell: tuple[int, int]                          # (row, col) of the reading this chip feeds
    position_mm: tuple[float, float]               # chip centre (x, y) in the pad frame, mm
    axes: tuple[str, str, str] | None = None       # pad axis of the chip's x, y, z; default ("+x", "+y", "+z")
    rotation_deg: float = 0.0                      # in-plane turn chip -> pad axes, deg (when axes is not given)

    def __post_init__(self) -> None:
        for i, v in enumerate(self.position_mm):
            if not (isinstance(v, (int, float)) and (math.isfinite(v) or math.isnan(v))):
                raise ValueError(f"position_mm[{i}] must be a number, got {v!r}")
        if sum(math.isnan(v) for v in self.position_mm) == 1:
            raise ValueError(f"position_mm must be two finite numbers (x, y in mm), or both nan for a chip whose "
                             f"place is unknown; got [{', '.join(repr(float(v)) for v in self.position_mm)}]")
        _finite("rotation_deg", self.rotation_deg, low=-360.0, high=360.0, low_open=False)
        if self.axes is not None:
            if self.rotation_deg:
                raise ValueError("give either axes or rotation_deg, not both")
            axis_matrix(self.axes)

    def matrix(self) -> np.ndarray:
        """(3, 3) chip axes -> pad axes (exact zeros at right angles, so saturation maps channel to channel)."""
        if self.axes is not None:
            return axis_matrix(self.axes)
        a = math.radians(self.rotation_deg)
        m = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
        m[np.abs(m) < 1e-12] = 0.0
        return m


@dataclass(frozen=True)
class ChipGridSpec:
    """Chips row-major over a rows x cols grid centred on the pad, axes along the pad's (a SuperMag or uSkin
    type grid); the short form of listing each chip."""

    rows: int
    cols: int
    pitch_mm: float

    def __post_init__(self) -> None:
        for name in ("rows", "cols"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= 64:
                raise ValueError(f"chip_grid.{name} must be an integer from 1 to 64, got {value!r}")
        _finite("chip_grid.pitch_mm", self.pitch_mm, low=0.0, high=1000.0)

    def chips(self) -> tuple[ChipSpec, ...]:
        r0, c0 = (self.rows - 1) / 2, (self.cols - 1) / 2
        return tuple(ChipSpec(cell=(r, c), position_mm=((c - c0) * self.pitch_mm, (r0 - r) * self.pitch_mm))
                     for r in range(self.rows) for c in range(self.cols))


@dataclass(frozen=True)
class WireSpec:
    """How the board's frames travel: the serial backend's wire format and the baud rate."""

    format: str = "supermag"  # a name of tactile_manip.wire.WIRE_FORMATS
    baudrate: int = 921600

    def __post_init__(self) -> None:
        if self.format not in WIRE_FORMATS:
            raise ValueError(f"wire.format must be one of {', '.join(WIRE_FORMATS)}, got {self.format!r}")
        if not isinstance(self.baudrate, int) or not 300 <= self.baudrate <= 20_000_000:
            raise ValueError(f"wire.baudrate must be an integer from 300 to 20000000, got {self.baudrate!r}")


@dataclass(frozen=True)
class MagnetSpec:
    """One discrete permanent magnet, axis-aligned, uniformly polarised.

    ``size_mm``: (diameter, height) of a cylinder (its axis along the pad normal), or (x, y, z) of a cuboid.
    ``polarisation_t``: J = mu0 M in tesla, pad axes (a N52 magnet along +z: about (0, 0, 1.4)).
    """

    shape: Literal["cylinder", "cuboid"]
    size_mm: tuple[float, ...]
    position_mm: tuple[float, float, float]       # centre, pad frame, mm
    polarisation_t: tuple[float, float, float]    # T

    def __post_init__(self) -> None:
        n = 2 if self.shape == "cylinder" else 3
        if len(self.size_mm) != n:
            raise ValueError(f"a {self.shape} magnet's size_mm has {n} values "
                             f"({'diameter, height' if n == 2 else 'x, y, z'}), got {list(self.size_mm)}")
        for i, v in enumerate(self.size_mm):
            _finite(f"size_mm[{i}]", v, low=0.0, high=1000.0)
        for i, v in enumerate(self.position_mm):
            _finite(f"position_mm[{i}]", v, low=-1000.0, high=1000.0, low_open=False)
        for i, v in enumerate(self.polarisation_t):
            _finite(f"polarisation_t[{i}]", v, low=-2.0, high=2.0, low_open=False)
        if not any(self.polarisation_t):
            raise ValueError("polarisation_t is zero: a magnet needs a polarisation")


@dataclass(frozen=True)
class BodySpec:
    """The magnetic body: a magnetised layer (the compliant layer itself, polarised along its normal; ReSkin,
    AnySkin, SuperMag) or discrete magnets embedded in the layer (eFlesh)."""

    kind: Literal["layer", "magnets"]
    remanence_t: float = 0.0                      # kind "layer": polarisation along +z, T
    magnets: tuple[MagnetSpec, ...] = ()          # kind "magnets"

    def __post_init__(self) -> None:
        if self.kind == "layer":
            _finite("body.remanence_t", self.remanence_t, low=0.0, high=2.0)
            if self.magnets:
                raise ValueError("body.magnets belongs to kind = \"magnets\"; a magnetised layer has none")
        else:
            if not self.magnets:
                raise ValueError("body kind \"magnets\" needs at least one [[body.magnets]] entry")
            if self.remanence_t:
                raise ValueError("body.remanence_t belongs to kind = \"layer\"; give each magnet's polarisation_t")


@dataclass(frozen=True)
class LayerSpec:
    """The compliant layer, bonded to a rigid base, and the chips' depth below it."""

    size_mm: tuple[float, float]   # in-plane size (x, y), mm
    thickness_mm: float            # mm
    modulus_kpa: float             # Young's modulus (incompressible), kPa
    gap_mm: float                  # from the layer's base down to the chips' sensing plane, mm

    def __post_init__(self) -> None:
        for i, v in enumerate(self.size_mm):
            _finite(f"layer.size_mm[{i}]", v, low=0.0, high=1000.0)
        _finite("layer.thickness_mm", self.thickness_mm, low=0.0, high=100.0)
        _finite("layer.modulus_kpa", self.modulus_kpa, low=0.0, high=1e6)
        _finite("layer.gap_mm", self.gap_mm, low=0.0, high=100.0, low_open=False)


@dataclass(frozen=True)
class ReadoutSpec:
    """One chip's readout in a fitted board: its reading (chip axes, uT) is ``matrix @ B + offset_ut`` for the field
    ``B`` at the chip in pad axes (the matrix holds the chip's turn, gain and misalignment)."""

    matrix: tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]
    offset_ut: tuple[float, float, float] = (0.0, 0.0, 0.0)   # uT, chip axes

    def __post_init__(self) -> None:
        for i, row in enumerate(self.matrix):
            for j, v in enumerate(row):
                _finite(f"twin.readout.matrix[{i}][{j}]", v, low=-100.0, high=100.0, low_open=False)
        for i, v in enumerate(self.offset_ut):
            _finite(f"twin.readout.offset_ut[{i}]", v, low=-1e5, high=1e5, low_open=False)
        if abs(np.linalg.det(np.array(self.matrix, float))) < 1e-9:
            raise ValueError("twin.readout.matrix is singular: a chip's readout must see every field direction")


@dataclass(frozen=True)
class TwinSpec:
    """The ``[twin]`` table: a board fitted to a probe rig's logs (:mod:`tactile_manip.sim.twin`)."""

    rig_origin_mm: tuple[float, float]     # stage (x, y) of the pad origin, mm
    rig_turn_deg: float                    # turn of the stage axes onto the pad's, deg (counter-clockwise)
    contact_z_mm: float                    # stage z at first touch, mm
    press_gain: float                      # A in s = A d^n: press strength per approach^n, mm^(2-n)
    press_exponent: float                  # n
    kernel_depth_mm: float                 # depth of the press kernel below the surface, mm
    depth_per_z: float = -1.0              # approach per mm of stage z (-1: a smaller z is deeper)
    rig_mirror: bool = False               # the stage's y axis is mirrored before the turn (a left-handed rig)
    lateral_scale: float = 1.0             # scale of the in-plane displacement against an isotropic solid
    tilt_scale: float = 1.0                # scale of the magnets' turn against curl(u) / 2
    softening_per_hour: float = 0.0        # the press strength grows by this share per hour of the run
    base_image: float = 0.0                # share of the press's image in the rigid base the layer is bonded to
    cell_period_mm: float = 0.0            # pitch of the printed lattice's nodes, mm (0: no lattice term)
    cell_angle_deg: float = 0.0            # turn of the lattice's rows from the pad's x axis, deg
    cell_phase: tuple[float, float] = (0.0, 0.0)  # a node's place along the lattice's two axes, periods
    cell_sharpness: float = 1.0            # how narrow a node's region is (the power of its raised cosines)
    cell_stiffness: float = 0.0            # log of the press strength's factor on a node
    cell_depth: float = 0.0                # log of the kernel depth's factor on a node
    cell_tilt: float = 0.0                 # log of the tilt scale's factor on a node
    readout: tuple[ReadoutSpec, ...] = ()  # one per chip, firmware order; empty: the chips' axis maps

    def __post_init__(self) -> None:
        for i, v in enumerate(self.rig_origin_mm):
            _finite(f"twin.rig_origin_mm[{i}]", v, low=-1e4, high=1e4, low_open=False)
        _finite("twin.rig_turn_deg", self.rig_turn_deg, low=-360.0, high=360.0, low_open=False)
        _finite("twin.contact_z_mm", self.contact_z_mm, low=-1e4, high=1e4, low_open=False)
        _finite("twin.press_gain", self.press_gain, low=0.0, high=1e4)
        _finite("twin.press_exponent", self.press_exponent, low=0.0, high=5.0)
        _finite("twin.kernel_depth_mm", self.kernel_depth_mm, low=0.0, high=1000.0)
        _finite("twin.depth_per_z", self.depth_per_z, low=-100.0, high=100.0, low_open=False)
        if self.depth_per_z == 0.0:
            raise ValueError("twin.depth_per_z is 0: the stage's z must move the probe in (-1 or +1, usually)")
        _finite("twin.lateral_scale", self.lateral_scale, low=0.0, high=100.0, low_open=False)
        _finite("twin.tilt_scale", self.tilt_scale, low=0.0, high=100.0, low_open=False)
        _finite("twin.softening_per_hour", self.softening_per_hour, low=-1.0, high=10.0, low_open=False)
        _finite("twin.base_image", self.base_image, low=0.0, high=1.0, low_open=False)
        _finite("twin.cell_period_mm", self.cell_period_mm, low=0.0, high=1000.0, low_open=False)
        _finite("twin.cell_angle_deg", self.cell_angle_deg, low=-360.0, high=360.0, low_open=False)
        for i, v in enumerate(self.cell_phase):
            _finite(f"twin.cell_phase[{i}]", v, low=-100.0, high=100.0, low_open=False)
        _finite("twin.cell_sharpness", self.cell_sharpness, low=0.0, high=1000.0)
        for name in ("cell_stiffness", "cell_depth", "cell_tilt"):
            _finite(f"twin.{name}", getattr(self, name), low=-10.0, high=10.0, low_open=False)


@dataclass(frozen=True)
class BoardHeader:
    """The ``[board]`` table."""

    name: str
    grid: tuple[int, int]            # (rows, cols) of the reading
    pitch_mm: float                  # distance between neighbouring reading cells, mm (plots)
    description: str = ""
    source: str = ""                 # where the geometry and figures come from

    def __post_init__(self) -> None:
        if not self.name or self.name != self.name.strip() or any(c in self.name for c in "/\\\n"):
            raise ValueError(f"board.name must be a plain name, got {self.name!r}")
        if not self.name.isprintable() or any(unicodedata.category(c) in ("Cf", "Cc", "Zl", "Zp") for c in self.name):
            raise ValueError(f"board.name must be printable, without control or formatting characters, got "
                             f"{self.name.encode('unicode_escape').decode()!r}")
        if not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 64 for v in self.grid):
            raise ValueError(f"board.grid must be two integers from 1 to 64, got {list(self.grid)}")
        _finite("board.pitch_mm", self.pitch_mm, low=0.0, high=1000.0)


@dataclass(frozen=True)
class BoardFile:
    """A board file's tables (see the module docstring); :class:`~tactile_manip.boards.load.Board` is the
    checked board built from one."""

    board: BoardHeader
    chips: tuple[ChipSpec, ...] = ()
    chip_grid: ChipGridSpec | None = None
    chip: ChipModelSpec = field(default_factory=ChipModelSpec)
    wire: WireSpec = field(default_factory=WireSpec)
    body: BodySpec | None = None
    layer: LayerSpec | None = None
    twin: TwinSpec | None = None
    fit: dict[str, Any] | None = None
