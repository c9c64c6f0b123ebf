"""Episodes of timed frames: what every exporter and viewer of ``tactile_manip.interop`` reads.

A source (a trial run's frame stream, a sensor recording, a collector's pair log) becomes a list of
:class:`Episode`; the LeRobot, Rerun and MCAP writers consume episodes and know nothing of where they came
from. Frames sit on the sensor clock: ``t_s`` is seconds from the episode's first frame, on the fixed grid
``index / fps``; the host's wall time is kept beside it as its own value.

Shapes and units (R x C taxels of 3 axes, H x W depth pixels):

- ``field_ut`` (R, C, 3) float32 microtesla, baseline-subtracted, axes (x, y, z) in the pad frame;
- ``depth_mm`` / ``vbts_depth_mm`` (H, W) float32 millimetres of indentation;
- ``joints_rad`` (7,) float64, ``gripper_width_m`` float, ``target_angle_rad`` float (the commanded
  in-hand angle), angles axial in (-pi/2, pi/2].

This module imports numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

PHASES = ("", "grasp", "estimate", "turn", "release")


@dataclass
class Frame:
    """One time step of an episode; optional streams are None (or NaN for scalars) where a source lacks them.

    Attributes:
        t_s: sensor-clock time from the episode's first frame, s (``index / fps``).
        host_time_s: the recording host's clock when the frame arrived, s.
        field_ut: (R, C, 3) float32 reading, uT.
        angle_rad: in-hand angle estimate, rad; NaN where none was made at this frame.
        confidence: the estimate's confidence in [0, 1]; NaN where none.
        joints_rad: (7,) arm joint positions, rad, or None without an arm.
        gripper_width_m: gripper opening, m; NaN without a gripper.
        target_angle_rad: the commanded in-hand angle (the action), rad; NaN where none.
        phase: one of PHASES ("" outside a trial).
        depth_mm: (H, W) reconstructed depth, mm, or None.
        vbts_depth_mm: (H, W) depth measured by the vision-based sensor (pair logs), mm, or None.
        field_raw_ut: (R, C, 3) float32 field before the baseline was subtracted, uT, or None where the source
            does not keep it apart (a recording holds raw fields only: its ``field_ut`` is raw).
    """

    t_s: float
    host_time_s: float
    field_ut: np.ndarray
    angle_rad: float = math.nan
    confidence: float = math.nan
    joints_rad: np.ndarray | None = None
    gripper_width_m: float = math.nan
    target_angle_rad: float = math.nan
    phase: str = ""
    depth_mm: np.ndarray | None = None
    vbts_depth_mm: np.ndarray | None = None
    field_raw_ut: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.field_ut.ndim != 3 or self.field_ut.shape[-1] != 3:
            raise ValueError(f"field_ut: expected shape (rows, cols, 3), got {self.field_ut.shape}")
        if self.phase not in PHASES:
            raise ValueError(f"phase: expected one of {PHASES}, got {self.phase!r}")


@dataclass
class Episode:
    """Frames of one trial and method (or one recording), on the sensor clock at ``fps``.

    Attributes:
        index: episode index within the export (0, 1, ...).
        task: the task in words, e.g. "reorient rod_hex_4mm to 0.0 deg (supermag)".
        fps: sensor frame rate, Hz.
        frames: the frames in time order.
        success: the trial's outcome, or None where there is none (a recording).
        meta: JSON-able facts of the source (trial record, layout name, calibration, model), kept as is.
    """

    index: int
    task: str
    fps: float
    frames: list[Frame]
    success: bool | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not (self.fps > 0 and math.isfinite(self.fps)):
            raise ValueError(f"fps: expected a positive rate in Hz, got {self.fps}")

    @property
    def grid(self) -> tuple[int, int]:
        """Taxel rows and columns (R, C) of the first frame; (0, 0) for an empty episode."""
        if not self.frames:
            return 0, 0
        rows, cols, _ = self.frames[0].field_ut.shape
        return int(rows), int(cols)
