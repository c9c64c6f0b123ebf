"""The magnetometer chip's hardware spec: LSB sizes, output rail, frame rate and rated noise.

One place for the datasheet numbers that the simulator, the serial drivers and the estimators all read:

- :class:`ChipModelSpec`: a chip model at one gain and resolution (a board file's ``[chip]`` table);
- :data:`MLX90393`: the MLX90393 at ReSkin's settings, the default everywhere;
- :class:`ChipSettings`: what code that converts counts or judges noise needs from a chip. A
  :class:`ChipModelSpec` has it, and so has the simulator's ``ChipParams`` (which adds the simulation-only
  Earth field, drift and misalignment), so either may be handed in;
- :func:`full_scale_ut` and :func:`as_chip_spec`.

numpy only, like every core module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

_SETTINGS = ("lsb_xy_ut", "lsb_z_ut", "saturation_counts", "rate_hz", "noise_xy_ut", "noise_z_ut")


class ChipSettings(Protocol):
    """A chip's conversion and noise figures, read-only (:class:`ChipModelSpec`, or the simulator's
    ``ChipParams``)."""

    @property
    def lsb_xy_ut(self) -> float: ...  # x and y sensitivity, uT per LSB

    @property
    def lsb_z_ut(self) -> float: ...  # z sensitivity, uT per LSB

    @property
    def saturation_counts(self) -> int: ...  # output rail, LSB

    @property
    def rate_hz(self) -> float: ...  # frames per second

    @property
    def noise_xy_ut(self) -> float: ...  # rated RMS noise of x and y, uT

    @property
    def noise_z_ut(self) -> float: ...  # rated RMS noise of z, uT


def _check_number(where: str, value: object, *, high: float, low_open: bool) -> None:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise ValueError(f"{where} must be a finite number, got {value!r}")
    if value <= 0.0 if low_open else value < 0.0:
        raise ValueError(f"{where} must be {'>' if low_open else '>='} 0.0, got {value}")
    if value > high:
        raise ValueError(f"{where} must be <= {high}, got {value}")


@dataclass(frozen=True)
class ChipModelSpec:
    """The magnetometer at the board's settings (default: MLX90393 at ReSkin's gain and resolution).

    Raises:
        ValueError: a field that is not a finite number in its range, naming it as ``chip.<field>``.
    """

    model: str = "MLX90393"
    lsb_xy_ut: float = 0.200        # x and y sensitivity, uT per LSB (datasheet sensitivity table)
    lsb_z_ut: float = 0.323         # z sensitivity, uT per LSB
    saturation_counts: int = 32767  # output rail, LSB (signed 16-bit output register)
    rate_hz: float = 125.0          # frames per second the firmware sends
    noise_xy_ut: float = 1.5        # rated RMS noise of x and y, uT (what a press of a simulated board adds)
    noise_z_ut: float = 2.5         # rated RMS noise of z, uT

    def __post_init__(self) -> None:
        for name in ("lsb_xy_ut", "lsb_z_ut", "rate_hz"):
            _check_number(f"chip.{name}", getattr(self, name), high=1e4, low_open=True)
        for name in ("noise_xy_ut", "noise_z_ut"):
            _check_number(f"chip.{name}", getattr(self, name), high=1e4, low_open=False)
        if (not isinstance(self.saturation_counts, int) or isinstance(self.saturation_counts, bool)
                or not 0 < self.saturation_counts < 1 << 31):
            raise ValueError(f"chip.saturation_counts must be an integer from 1 to 2**31 - 1, "
                             f"got {self.saturation_counts!r}")

    @property
    def full_scale_ut(self) -> tuple[float, float, float]:
        """The largest |field| each axis reports before its rail, uT."""
        return tuple(float(v) for v in full_scale_ut(self))  # type: ignore[return-value]


MLX90393 = ChipModelSpec()  # the MLX90393 at ReSkin's gain and resolution


def full_scale_ut(chip: ChipSettings) -> np.ndarray:
    """The largest field each axis can report, uT: (3,) ``saturation_counts x LSB`` for (x, y, z).

    For :data:`MLX90393` (int16 rail, 0.200 / 0.323 uT/LSB) that is 6553 uT (x, y) and 10584 uT (z); a value
    beyond it did not come from the chip.
    """
    return chip.saturation_counts * np.array([chip.lsb_xy_ut, chip.lsb_xy_ut, chip.lsb_z_ut])


def as_chip_spec(chip: ChipSettings) -> ChipModelSpec:
    """``chip`` itself when it is a :class:`ChipModelSpec`, else one with its :class:`ChipSettings` fields
    (the simulator's ``ChipParams`` loses its simulation-only fields; the model defaults to the MLX90393)."""
    if isinstance(chip, ChipModelSpec):
        return chip
    model = getattr(chip, "model", MLX90393.model)
    return ChipModelSpec(model=model, **{name: getattr(chip, name) for name in _SETTINGS})
