"""Every physical parameter of the paired-sensor simulator: default, unit, source and randomisation range.

This is the one place where the simulator's own numbers live: its settings, and the ranges it randomises the
physical quantities over. What the board is (its chips, their pitch and model, the layer's size, thickness and
modulus, the magnet's remanence, the chips' gap below the layer) comes from the board file
(:mod:`tactile_manip.boards`; the SuperMag pad is ``supermag-4x4.toml``): a field whose default is None takes
the board's value, filled in by :func:`for_board`. Each field carries metadata:

- ``unit``: the unit (also in the field name where it is not SI);
- ``source``: where the default comes from;
- ``rand``: the ``(low, high)`` range used by :func:`randomise` for domain randomisation, or ``None`` for a
  parameter that is a design choice rather than an uncertain physical quantity;
- ``log``: draw log-uniformly (for scale-like quantities spanning a decade);
- ``limits``: the open interval of values the physics accepts at all (checked in ``__post_init__``).

All parameter sets are frozen dataclasses; use :func:`dataclasses.replace` or :func:`randomise` to derive
variants. ``SimParams`` mirrors the ``[sim]`` table of the dataset configs.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from tactile_manip.boards import Board
from tactile_manip.chips import ChipModelSpec, as_chip_spec

_INF = math.inf


def param(default: Any, *, unit: str, source: str, rand: tuple[float, float] | None = None,
          log: bool = False, limits: tuple[float, float] = (0.0, _INF)) -> Any:
    """Declare a simulator parameter with its unit, source, randomisation range and valid open interval."""
    return field(default=default, metadata={"unit": unit, "source": source, "rand": rand, "log": log,
                                            "limits": limits})


class _Validated:
    """Checks every numeric field against its ``limits`` and its ``rand`` range on construction (None: the
    board's value, not filled in yet)."""

    def __post_init__(self) -> None:
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            meta = f.metadata
            choices = typing.get_args(hints[f.name]) if typing.get_origin(hints[f.name]) is Literal else ()
            if choices and value not in choices:
                raise ValueError(f"{type(self).__name__}.{f.name} must be one of {list(choices)}, got {value!r}")
            if "limits" not in meta or value is None or isinstance(value, str) or isinstance(value, bool):
                continue
            lo, hi = meta["limits"]
            where = f"{type(self).__name__}.{f.name}"
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{where} must be a finite number, got {value!r}")
            if not lo < value < hi:
                raise ValueError(f"{where} = {value} is outside the allowed open interval ({lo}, {hi}) "
                                 f"[{meta['unit']}]")
            rand = meta["rand"]
            if rand is not None and not lo < rand[0] <= rand[1] < hi:
                raise ValueError(f"{where}: randomisation range {rand} must lie inside ({lo}, {hi})")


@dataclass(frozen=True)
class LayerParams(_Validated):
    """The moduli of the elastic contact module shared by both sensors (bonded to a rigid base, frictionless top);
    its size and thickness are the board's ``[layer]``."""

    vbts_modulus_kpa: float = param(
        118.0, unit="kPa", rand=(85.0, 125.0),
        source="Ecoflex 00-30: datasheet 100 % secant modulus 69 kPa; a neo-Hookean solid has a secant "
               "modulus of 0.58 E at 100 % strain, so E ~ 118 kPa. The design range is 50-125 kPa "
               "(docs/design.md); below ~85 kPa the Allen key at 10-11 N is pushed through >85 % of the "
               "2.5 mm layer, outside the linear model, so the randomisation range starts there")
    skin_modulus_kpa: float | None = param(
        None, unit="kPa", rand=(120.0, 300.0),
        source="the board's layer.modulus_kpa (SuperMag: Ecoflex 00-30 with MQP-15-7 powder, 3:1:1 by weight, "
               "Sec. III-B, 200 kPa); particle loading stiffens silicone about 2-4x (ReSkin-style skins)")


@dataclass(frozen=True)
class ContactParams(_Validated):
    """Numerical settings of the Polonsky-Keer force-controlled contact solver."""

    pixel_mm: float = param(0.25, unit="mm", limits=(1e-3, 5.0),
                            source="design choice: 80x80 cells on the pad; grid-size invariance tested "
                                   "against 0.125 mm")
    max_iterations: int = param(300, unit="1", limits=(0, 100_000),
                                source="design choice: flat punches need ~60, smooth bodies ~25")
    tolerance: float = param(1e-5, unit="1", limits=(0.0, 1.0),
                             source="design choice: relative L1 change of pressure between iterations")


@dataclass(frozen=True)
class VbtsParams(_Validated):
    """DTact-style vision-based sensor: depth pipeline artefacts on the rigid imprint."""

    image_px: int = param(200, unit="px", limits=(1, 10_000), source="SuperMag Sec. III-D: 200x200 images")
    pixel_mm: float = param(0.1, unit="mm", limits=(1e-4, 10.0),
                            source="20 mm pad over 200 px (SuperMag Sec. III-D)")
    lookup_table: Literal["sensor_1", "sensor_2"] = field(
        default="sensor_1",
        metadata={"unit": "-", "source": "measured DTact grey-to-depth tables (9DTact, MIT); sensor_1 "
                                         "saturates at 1.92 mm, sensor_2 at 1.35 mm", "rand": None})
    dead_band_levels: int = param(2, unit="grey levels", limits=(-1, 255),
                                  source="DTact lighting threshold: differences below 2 levels read as 0")
    noise_grey_levels: float = param(1.0, unit="grey levels", rand=(0.5, 2.0), limits=(-1e-12, 255.0),
                                     source="camera read noise ~1 grey level (docs/design.md)")
    blur_sigma_mm: float = param(0.07, unit="mm", rand=(0.05, 0.1), limits=(-1e-12, 10.0),
                                 source="DTact depth smoothing, three Gaussian passes (docs/design.md)")
    blur_passes: int = param(3, unit="1", limits=(-1, 100), source="DTact depth smoothing (docs/design.md)")


@dataclass(frozen=True)
class MagnetParams(_Validated):
    """The magnetic body's strength, the chips' gap below it, and a magnetised layer's dipole cells."""

    remanence_t: float | None = param(None, unit="T", rand=(0.03, 0.055),
                                      source="the board's body.remanence_t, or its magnets' mean polarisation "
                                             "(every magnet scales with it); the range: J_r of MQP-15-7 "
                                             "silicone composites (ReSkin-style skins; design range "
                                             "0.03-0.11 T, docs/design.md), capped at 0.055 T because above it "
                                             "the SuperMag corner chips' z channel saturates (tested)")
    chip_gap_mm: float | None = param(None, unit="mm", rand=(0.8, 2.0), limits=(1e-3, 100.0),
                                      source="the board's layer.gap_mm; the range: skin-to-die distance of "
                                             "MLX90393 under a ReSkin skin (design range 0.5-2.0 mm, "
                                             "docs/design.md); below 0.8 mm the SuperMag corner chips saturate "
                                             "at J_r 0.055 T")
    cell_mm: float = param(0.5, unit="mm", limits=(1e-3, 5.0),
                           source="design choice: dipole cells 0.4-0.5 mm converge to <2 % (tested)")
    thickness_nodes: int = param(6, unit="1", limits=(0, 64),
                                 source="design choice: Gauss-Legendre nodes through the skin")
    transport: Literal["rotation", "affine"] = field(
        default="rotation",
        metadata={"unit": "-", "rand": None,
                  "source": "how a cell's moment follows the deformation: 'rotation' turns it by the exact "
                            "rotation of omega = curl(u)/2; 'affine' maps it by the deformation gradient"})


@dataclass(frozen=True)
class ChipParams(_Validated):
    """The magnetometers as the simulator draws them.

    The hardware figures (LSB sizes, rail, rate, rated noise) default to the board's ``[chip]`` (None until
    :func:`for_board`); Earth field, drift and misalignment are the simulation's own. :meth:`spec` is the
    hardware part.
    """

    lsb_xy_ut: float | None = param(None, unit="uT/LSB", source="the board's chip.lsb_xy_ut")
    lsb_z_ut: float | None = param(None, unit="uT/LSB", source="the board's chip.lsb_z_ut")
    noise_xy_ut: float | None = param(None, unit="uT", rand=(1.5, 15.0), log=True, limits=(-1e-12, 1e4),
                                      source="the board's chip.noise_xy_ut (MLX90393 datasheet RMS noise); up to "
                                             "10-17 uT in idle eFlesh recordings")
    noise_z_ut: float | None = param(None, unit="uT", rand=(2.5, 15.0), log=True, limits=(-1e-12, 1e4),
                                     source="the board's chip.noise_z_ut (MLX90393 datasheet RMS noise); up to "
                                            "10-17 uT in idle eFlesh recordings")
    earth_field_ut: float = param(50.0, unit="uT", rand=(25.0, 65.0), limits=(-1e-12, 1e4),
                                  source="geomagnetic field magnitude, 25-65 uT worldwide")
    drift_ut: float = param(5.0, unit="uT", rand=(0.0, 10.0), limits=(-1e-12, 1e4),
                            source="per-press baseline drift (temperature, hysteresis; docs/design.md)")
    rotation_deg: float = param(0.0, unit="deg", rand=(0.0, 3.0), limits=(-1e-12, 45.0),
                                source="RMS mounting misalignment of each chip; 0 = ideal board")
    saturation_counts: int | None = param(None, unit="LSB", limits=(0, 1 << 31),
                                          source="the board's chip.saturation_counts")
    rate_hz: float | None = param(None, unit="Hz", source="the board's chip.rate_hz")

    def spec(self) -> ChipModelSpec:
        """The hardware part (LSB sizes, rail, rate, rated noise) as the core chip spec, for the drivers.

        Raises:
            ValueError: a figure not filled in from a board yet (see :func:`for_board`).
        """
        missing = [name for name in _BOARD_CHIP if getattr(self, name) is None]
        if missing:
            raise ValueError(f"ChipParams.{missing[0]} is not set: fill the board's figures in with for_board()")
        return as_chip_spec(self)


_BOARD_CHIP = ("lsb_xy_ut", "lsb_z_ut", "noise_xy_ut", "noise_z_ut", "saturation_counts", "rate_hz")


@dataclass(frozen=True)
class SimParams:
    """All parameters of a :class:`~tactile_manip.sim.pair.SensorPair` (None fields: the board's values)."""

    layer: LayerParams = field(default_factory=LayerParams)
    contact: ContactParams = field(default_factory=ContactParams)
    vbts: VbtsParams = field(default_factory=VbtsParams)
    magnet: MagnetParams = field(default_factory=MagnetParams)
    chip: ChipParams = field(default_factory=ChipParams)


def for_board(board: Board, params: SimParams | None = None) -> SimParams:
    """``params`` (default: :class:`SimParams`) with every field it leaves None set to ``board``'s value: the
    layer's modulus, the body's remanence (a magnet body's: its magnets' mean polarisation), the chips' gap,
    LSB sizes, rail, rate and rated noise.

    Raises:
        ConfigError: the board cannot be simulated (no ``[body]`` / ``[layer]``, or ``generic:N``).
    """
    board.require_simulation()
    params = params or SimParams()
    layer, body, chip = board.layer, board.body, board.chip
    assert layer is not None and body is not None  # require_simulation() saw to it
    nominal = {"layer": {"skin_modulus_kpa": layer.modulus_kpa},
               "magnet": {"remanence_t": nominal_remanence_t(board), "chip_gap_mm": layer.gap_mm},
               "chip": {name: getattr(chip, name) for name in _BOARD_CHIP}}
    changes = {}
    for group, values in nominal.items():
        part = getattr(params, group)
        fill = {name: value for name, value in values.items() if getattr(part, name) is None}
        changes[group] = dataclasses.replace(part, **fill) if fill else part
    return dataclasses.replace(params, **changes)


def nominal_remanence_t(board: Board) -> float:
    """The remanence that :attr:`MagnetParams.remanence_t` scales from: a magnetised layer's, or the mean
    polarisation magnitude of a board's magnets, T."""
    body = board.body
    assert body is not None
    if body.kind == "layer":
        return body.remanence_t
    return float(np.mean([np.linalg.norm(m.polarisation_t) for m in body.magnets]))


def randomise(params: Any, rng: np.random.Generator, *, spread: float = 1.0) -> Any:
    """Return a copy of ``params`` (any parameter dataclass, nested) with every randomisable field drawn.

    Each field with a ``rand`` range is drawn uniformly (log-uniformly where ``log``) from the range
    shrunk about the default by ``spread`` in [0, 1]; ``spread=0`` returns the defaults unchanged. Give it
    parameters filled in from a board (:func:`for_board`).
    """
    if not 0.0 <= spread <= 1.0:
        raise ValueError(f"spread must be in [0, 1], got {spread}")
    changes = {}
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if dataclasses.is_dataclass(value):
            changes[f.name] = randomise(value, rng, spread=spread)
            continue
        rand = f.metadata.get("rand")
        if rand is None:
            continue
        if value is None:
            raise ValueError(f"{type(params).__name__}.{f.name} is the board's: fill it in with for_board() "
                             "before randomising")
        lo, hi = (math.log(rand[0]), math.log(rand[1])) if f.metadata["log"] else rand
        centre = math.log(value) if f.metadata["log"] and value > 0 else value
        lo, hi = centre + spread * (lo - centre), centre + spread * (hi - centre)
        x = rng.uniform(min(lo, hi), max(lo, hi))
        changes[f.name] = math.exp(x) if f.metadata["log"] else x
    return dataclasses.replace(params, **changes)


def randomised_values(params: Any) -> dict[str, float]:
    """The randomisable fields of a parameter tree by dotted name (``"magnet.remanence_t"``), in field order:
    what :func:`randomise` draws, for recording a drawn sensor next to the data it made."""
    return {row["name"]: float(row["value"]) for row in describe(params) if row["rand"] is not None}


def with_values(params: Any, values: dict[str, float], _prefix: str = "") -> Any:
    """A copy of ``params`` with the fields named in ``values`` (dotted names, as :func:`randomised_values`
    gives them) set: the sensor a dataset's ``sensor_params`` extra recorded, rebuilt.

    Raises:
        KeyError: a name that is not a field of ``params`` (the message names it).
    """
    nested: dict[str, dict[str, float]] = {}
    changes: dict[str, Any] = {}
    names = {f.name for f in dataclasses.fields(params)}
    for name, value in values.items():
        head, _, rest = name.partition(".")
        if head not in names:
            raise KeyError(f"{_prefix + name!r}: {type(params).__name__} has no field {head!r}")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            changes[head] = value
    for head, sub in nested.items():
        changes[head] = with_values(getattr(params, head), sub, f"{_prefix}{head}.")
    return dataclasses.replace(params, **changes)


def describe(params: Any, prefix: str = "") -> list[dict[str, Any]]:
    """Flatten a parameter tree into rows ``{name, value, unit, source, rand}`` (for docs and reports)."""
    rows = []
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value):
            rows.extend(describe(value, prefix=f"{name}."))
        else:
            rows.append({"name": name, "value": value, "unit": f.metadata.get("unit", ""),
                         "source": f.metadata.get("source", ""), "rand": f.metadata.get("rand")})
    return rows
