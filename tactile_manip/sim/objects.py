"""Rigid indenters as protrusion heightmaps and their pose on the pad.

An indenter is described in its local frame by ``height_mm[i, j]``: how far its pad-facing surface sticks
out toward the pad (larger touches first); NaN where there is no material. Arrays use the image layout of
the package: row 0 at local +y, column 0 at local -x, pixel centres at
``((j - (W-1)/2) * pixel_mm, ((H-1)/2 - i) * pixel_mm)``. ``origin_mm`` gives the local coordinates of the
object's reference point, which an :class:`IndenterPose` places on the pad.

The built-in shapes and the name registry live in :mod:`tactile_manip.sim.shapes`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from tactile_manip.checks import check_array, check_finite_scalar

MAX_TILT_RAD = 0.35
DEFAULT_PIXEL_MM = 0.05


@dataclass(frozen=True)
class IndenterPose:
    """Placement of an indenter's reference point on the pad (pad frame, mm and rad)."""

    x_mm: float = 0.0        # object origin in the pad frame, mm
    y_mm: float = 0.0        # mm
    yaw_rad: float = 0.0     # rotation about pad +z, counter-clockwise from +x, rad
    tilt_x_rad: float = 0.0  # tilt about the pad x axis (positive: the +y side protrudes more), rad
    tilt_y_rad: float = 0.0  # tilt about the pad y axis (positive: the -x side protrudes more), rad

    def __post_init__(self) -> None:
        for name in ("x_mm", "y_mm", "yaw_rad"):
            check_finite_scalar(f"IndenterPose.{name}", getattr(self, name))
        for name in ("tilt_x_rad", "tilt_y_rad"):
            check_finite_scalar(f"IndenterPose.{name}", getattr(self, name), low=-MAX_TILT_RAD, high=MAX_TILT_RAD)


class Indenter:
    """A rigid object given by its protrusion heightmap (see the module docstring for the layout)."""

    def __init__(self, height_mm: np.ndarray, pixel_mm: float, *, name: str = "heightmap",
                 origin_mm: tuple[float, float] = (0.0, 0.0)) -> None:
        height = check_array("height_mm", height_mm, allow_nan=True)
        if height.size == 0:
            raise ValueError(f"height_mm is empty (shape {height.shape}): an indenter needs some material")
        if height.ndim != 2 or min(height.shape) < 2:
            raise ValueError(f"height_mm must be a 2-D array of at least 2x2 pixels, got shape {height.shape}")
        if not np.isfinite(height).any():
            raise ValueError("height_mm has no finite value (all NaN): an indenter needs some material")
        self.height_mm = height.copy()
        self.height_mm.flags.writeable = False
        self.pixel_mm = check_finite_scalar("pixel_mm", pixel_mm, low=0.0, low_open=True)
        self.name = str(name)
        ox, oy = check_array("origin_mm", origin_mm, shape=(2,))
        self.origin_mm = (float(ox), float(oy))

    @classmethod
    def from_heightmap(cls, height_mm: np.ndarray, pixel_mm: float, *, name: str = "heightmap",
                       origin_mm: tuple[float, float] = (0.0, 0.0)) -> Indenter:
        """Build an indenter from a user heightmap (H, W) in mm sampled every ``pixel_mm``."""
        return cls(height_mm, pixel_mm, name=name, origin_mm=origin_mm)

    @classmethod
    def from_mesh(cls, path: str | Path, *, pixel_mm: float = DEFAULT_PIXEL_MM, name: str | None = None) -> Indenter:
        """Build an indenter from the lowest surface of a triangle mesh (mm), origin at its xy box centre."""
        from tactile_manip.sim.mesh import heightmap_from_mesh

        height, pixel = heightmap_from_mesh(path, pixel_mm=pixel_mm)
        return cls(height, pixel, name=Path(path).stem if name is None else name)

    @property
    def relief_mm(self) -> float:
        """Highest minus lowest protrusion over the material, mm."""
        return float(np.nanmax(self.height_mm) - np.nanmin(self.height_mm))

    def __repr__(self) -> str:
        h, w = self.height_mm.shape
        return f"Indenter(name={self.name!r}, shape=({h}, {w}), pixel_mm={self.pixel_mm}, origin_mm={self.origin_mm})"

    def protrusion_mm(self, x_mm: np.ndarray, y_mm: np.ndarray, pose: IndenterPose) -> np.ndarray:
        """Protrusion (mm) of the posed object at pad points ``(x_mm, y_mm)`` (any equal shapes).

        Bilinear in the heightmap, tilt included as ``y * tan(tilt_x) - x * tan(tilt_y)`` with x, y relative
        to the pose origin; NaN where the object has no material (bilinear sampling makes that up to one
        heightmap pixel wider than the material). 200x200 points take about 2 ms.
        """
        x, y = np.broadcast_arrays(np.asarray(x_mm, dtype=np.float64), np.asarray(y_mm, dtype=np.float64))
        dx, dy = x - pose.x_mm, y - pose.y_mm
        c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        lx = c * dx + s * dy + self.origin_mm[0]  # inverse yaw, then shift to array-centred coordinates
        ly = -s * dx + c * dy + self.origin_mm[1]
        h, w = self.height_mm.shape
        coords = np.stack([(h - 1) / 2.0 - ly / self.pixel_mm, lx / self.pixel_mm + (w - 1) / 2.0])
        out = ndimage.map_coordinates(self.height_mm, coords.reshape(2, -1), order=1, mode="constant",
                                      cval=np.nan, prefilter=False).reshape(x.shape)
        return out + dy * math.tan(pose.tilt_x_rad) - dx * math.tan(pose.tilt_y_rad)
