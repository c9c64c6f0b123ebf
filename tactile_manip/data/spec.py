"""What the numbers in a paired dataset mean: the readings' channels and the images' unit and range.

A :class:`ChannelSpec` names the channels of a reading (the last axis of ``readings`` (N, R, C, A)), their
unit and their kind. The kind decides how the sensor's symmetries act on them: the three components of a
magnetic field turn with the pad (a quarter turn maps (Bx, By) to (-By, Bx)); scalar channels (capacitance,
normalised counts, pressure) move with their taxel and keep their value.

An :class:`ImageSpec` gives the images' unit, the interval their values live in (its width is the data
range ``L`` of PSNR and SSIM everywhere a metric is computed), the pixel size, and how stored values map to
that unit (``value = stored * scale + offset``: the simulator stores depth as uint8 hundredths of a millimetre,
an imported float image is stored as is).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

CHANNEL_KINDS = ("magnetic_vector", "scalar")


@dataclass(frozen=True)
class ChannelSpec:
    """The channels of a reading (the last axis of ``readings``)."""

    names: tuple[str, ...] = ("x", "y", "z")   # one name per channel, in array order
    kind: str = "magnetic_vector"              # one of CHANNEL_KINDS
    unit: str = "uT"                           # unit of every channel ("uT", "pF", "counts", "1", ...)

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        if self.kind not in CHANNEL_KINDS:
            raise ValueError(f"channel kind must be one of {', '.join(CHANNEL_KINDS)}, got {self.kind!r}")
        if not self.names or len(set(self.names)) != len(self.names) or not all(self.names):
            raise ValueError(f"channel names must be distinct and non-empty, got {list(self.names)}")
        if self.kind == "magnetic_vector" and len(self.names) != 3:
            raise ValueError(f"a magnetic_vector reading has 3 channels (x, y, z in the pad frame), got "
                             f"{len(self.names)} {list(self.names)}; use kind 'scalar' for other channels")
        if not str(self.unit).strip():
            raise ValueError("channel unit must be a non-empty string (e.g. 'uT', 'pF', 'counts')")

    @property
    def count(self) -> int:
        return len(self.names)

    def index(self, name: str | None) -> int:
        """Index of channel ``name`` (None: the z channel of a magnetic field, else the first channel)."""
        if name is None:
            return 2 if self.kind == "magnetic_vector" else 0
        if name not in self.names:
            raise ValueError(f"no channel {name!r}; the readings have {list(self.names)}")
        return self.names.index(name)

    def to_dict(self) -> dict[str, Any]:
        return {"names": list(self.names), "kind": self.kind, "unit": self.unit}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ChannelSpec:
        return cls(names=tuple(d["names"]), kind=d["kind"], unit=d["unit"])


@dataclass(frozen=True)
class ImageSpec:
    """The images: unit, the interval [value_min, value_min + data_range], pixel size, storage scale."""

    unit: str = "mm"              # "mm" (depth of indentation), "fraction" (contact 0..1), "grey", ...
    data_range: float = 2.0       # width of the value interval, in `unit`: PSNR's and SSIM's L
    value_min: float = 0.0        # lowest valid value, in `unit`
    pixel_mm: float | None = 0.1  # pixel pitch on the pad, mm (None: unknown)
    scale: float = 1.0            # stored value -> unit: value = stored * scale + offset
    offset: float = 0.0

    def __post_init__(self) -> None:
        for name in ("data_range", "value_min", "scale", "offset"):
            value = float(getattr(self, name))
            if not math.isfinite(value):
                raise ValueError(f"image {name} must be finite, got {value}")
            object.__setattr__(self, name, value)
        if self.data_range <= 0:
            raise ValueError(f"image data_range must be > 0, got {self.data_range}")
        if self.scale <= 0:
            raise ValueError(f"image scale must be > 0, got {self.scale}")
        if self.pixel_mm is not None and not (math.isfinite(self.pixel_mm) and self.pixel_mm > 0):
            raise ValueError(f"image pixel_mm must be finite and > 0 (or unknown), got {self.pixel_mm}")
        if not str(self.unit).strip():
            raise ValueError("image unit must be a non-empty string (e.g. 'mm', 'fraction', 'grey')")

    @property
    def value_max(self) -> float:
        return self.value_min + self.data_range

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ImageSpec:
        return cls(**{k: d[k] for k in ("unit", "data_range", "value_min", "pixel_mm", "scale", "offset") if k in d})
