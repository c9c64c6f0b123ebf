"""Logging tactile frames to Rerun: the field as arrows, a Bz heat map, depth, angle and confidence over time.

:class:`RerunLogger` logs frames as they come (the live ``view --rerun`` and ``trials --rerun``);
:mod:`tactile_manip.interop.rerun_export` writes whole episodes column-wise with the same entity paths.
Entity paths for a sensor called ``name`` (default ``mbts``; all lengths in mm, the field in uT):

- ``tactile/<name>/taxels`` (static): Points3D at the taxel positions of the board layout, z = 0;
- ``tactile/<name>/field``: Arrows3D from each taxel, the (x, y, z) field times :data:`ARROW_MM_PER_UT`;
- ``tactile/<name>/bz``: Tensor (R, C) of Bz in uT (a heat map in the viewer);
- ``tactile/<name>/depth``: DepthImage (H, W) of the reconstructed depth in mm (``meter`` = 1000);
- ``tactile/<name>/angle_deg``, ``tactile/<name>/confidence``: Scalars, logged where an estimate exists;
- ``tactile/vbts/depth``: DepthImage of the vision-based sensor's measured depth (pair logs);
- ``robot/joints_rad`` (7 series), ``robot/gripper_width_mm``, ``trial/target_angle_deg`` (and, from
  ``trials --rerun``, ``trial/true_angle_deg``): Scalars;
  ``trial/phase`` and ``trial/episode``: TextLog lines when the phase or the episode changes.

Timelines: ``sensor_time`` (duration on the sensor clock), ``host_time`` (duration: the host's clock when the
frame arrived, as the source gives it), ``frame`` (sequence: the sensor's frame counter live, the row index
in exports), and in exports ``episode_time`` (from each episode's first frame).

Written for rerun-sdk 0.24 and later (``rr.set_time``, ``rr.Scalars``, ``rr.SeriesLines``, ``rr.TimeColumn``
and ``rr.send_columns`` all exist from 0.23 on). rerun is imported only inside the functions that use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

# arrow length per uT of field: a power of two, so vectors / ARROW_MM_PER_UT gives the logged field back
# exactly (float32); 2**-5 mm/uT draws 100 uT as 3.1 mm against the 5 mm taxel pitch
ARROW_MM_PER_UT = 2.0 ** -5
DEPTH_METER = 1000.0  # depth images are in mm: 1000 units per metre
DEPTH_RANGE_MM = (0.0, 2.0)  # the depth colour map's range: SuperMag's contacts stay within 2 mm
JOINT_NAMES = tuple(f"fr3_joint{i}" for i in range(1, 8))
APPLICATION_ID = "tactile_manip"


@dataclass(frozen=True)
class EntityPaths:
    """The entity paths of one tactile sensor (see the module docstring)."""

    name: str

    def __post_init__(self) -> None:
        if not self.name or not all(c.isalnum() or c in "_-" for c in self.name):
            raise ValueError(f"sensor name: expected letters, digits, '_' or '-', got {self.name!r}")

    @property
    def root(self) -> str:
        return f"tactile/{self.name}"

    @property
    def taxels(self) -> str:
        return f"{self.root}/taxels"

    @property
    def field(self) -> str:
        return f"{self.root}/field"

    @property
    def bz(self) -> str:
        return f"{self.root}/bz"

    @property
    def depth(self) -> str:
        return f"{self.root}/depth"

    @property
    def angle(self) -> str:
        return f"{self.root}/angle_deg"

    @property
    def confidence(self) -> str:
        return f"{self.root}/confidence"


VBTS_DEPTH = "tactile/vbts/depth"
JOINTS = "robot/joints_rad"
GRIPPER = "robot/gripper_width_mm"
TARGET = "trial/target_angle_deg"
TRUE_ANGLE = "trial/true_angle_deg"
PHASE = "trial/phase"
EPISODE = "trial/episode"


def require_rerun(purpose: str):
    """The ``rerun`` module (extra ``viz``), or MissingExtraError naming the extra."""
    from tactile_manip.extras import require

    return require("rerun", purpose)


def taxel_origins_mm(grid: tuple[int, int], layout: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """(R*C, 3) float32 taxel positions (x, y, 0) in mm and the (R*C,) bool mask of cells a chip feeds.

    ``layout``: a :class:`~tactile_manip.boards.Board` of this grid, or None for the default
    5 mm grid centred on the pad (row 0 at +y, column 0 at -x).
    """
    rows, cols = grid
    if layout is not None and tuple(layout.grid) == (rows, cols):
        xy = layout.positions_mm().reshape(-1, 2)
        mask = layout.mask.reshape(-1)
    else:
        c, r = np.meshgrid(np.arange(cols), np.arange(rows))
        xy = np.stack([(c - (cols - 1) / 2) * 5.0, ((rows - 1) / 2 - r) * 5.0], axis=-1).reshape(-1, 2)
        mask = np.ones(rows * cols, bool)
    origins = np.zeros((rows * cols, 3), np.float32)
    origins[:, :2] = np.nan_to_num(xy)
    return origins, mask


def arrows_from_field(field_ut: np.ndarray) -> np.ndarray:
    """(..., R, C, 3) uT -> (..., R*C, 3) float32 arrow vectors in mm (exactly invertible, see ARROW_MM_PER_UT)."""
    f = np.asarray(field_ut, dtype=np.float32)
    return (f * np.float32(ARROW_MM_PER_UT)).reshape(*f.shape[:-3], -1, 3)


def blueprint(paths: EntityPaths, *, robot: bool = False, depth: bool = True, vbts: bool = False):
    """The viewer layout: field arrows (3D) over the Bz heat map, the depth image(s), the angle and confidence
    plots; with ``robot`` the joints, gripper, target and the trial lines. Rerun's own layout would put the
    depth image into the 3D view of its parent, where it needs a camera."""
    import rerun.blueprint as rrb

    pad = rrb.Vertical(rrb.Spatial3DView(origin=paths.root, contents=[paths.taxels, paths.field],
                                         name=f"{paths.name} field (arrows: 1 mm per {1 / ARROW_MM_PER_UT:g} uT)"),
                       rrb.TensorView(origin=paths.bz, name="Bz (uT)"))
    images = [rrb.Spatial2DView(origin=paths.depth, name=f"{paths.name} depth (mm)")] if depth else []
    if vbts:
        images.append(rrb.Spatial2DView(origin=VBTS_DEPTH, name="VBTS depth (mm)"))
    series = [rrb.TimeSeriesView(origin=paths.angle, name="angle (deg)"),
              rrb.TimeSeriesView(origin=paths.confidence, name="confidence")]
    if robot:
        # joints and gripper apart: on one axis the width's tens of mm flatten the joints' radians
        series += [rrb.TimeSeriesView(origin=JOINTS, name="arm joints (rad)"),
                   rrb.TimeSeriesView(origin=GRIPPER, name="gripper width (mm)"),
                   rrb.TimeSeriesView(origin="trial", contents=[TARGET, TRUE_ANGLE], name="trial"),
                   rrb.TextLogView(origin="trial", name="trial log")]
    columns = [pad, rrb.Vertical(*images), rrb.Vertical(*series)] if images else [pad, rrb.Vertical(*series)]
    return rrb.Blueprint(rrb.Horizontal(*columns), collapse_panels=True)


def log_static(rr, recording, paths: EntityPaths, origins_mm: np.ndarray, *, robot: bool = True) -> None:
    """The parts that do not change: pad axes, taxel points, the names and styles of the time series."""
    rr.log(paths.root, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True, recording=recording)
    rr.log(paths.taxels, rr.Points3D(origins_mm, radii=0.4, colors=[150, 150, 150]), static=True,
           recording=recording)
    rr.log(paths.angle, rr.SeriesLines(names="angle (deg)"), static=True, recording=recording)
    rr.log(paths.confidence, rr.SeriesLines(names="confidence"), static=True, recording=recording)
    if robot:
        rr.log(JOINTS, rr.SeriesLines(names=list(JOINT_NAMES)), static=True, recording=recording)
        rr.log(GRIPPER, rr.SeriesLines(names="gripper width (mm)"), static=True, recording=recording)
        rr.log(TARGET, rr.SeriesLines(names="target angle (deg)"), static=True, recording=recording)


class RerunLogger:
    """Logs frames of one sensor to a Rerun recording as they come (see the module docstring for the paths).

    Fields are buffered and sent column-wise (``rr.send_columns``) every ``batch_frames`` frames, which costs
    a fraction of logging each frame on its own (``benchmarks/bench_rerun.py``); the viewer then trails the
    sensor by that many frames (12 at 125 Hz: 0.1 s). The Bz heat map, a Tensor, which cannot be sent
    column-wise, goes to the log for every ``heatmap_every``-th frame (the arrows carry Bz of every frame).
    Estimates, robot state and text are logged at once, at the time of the newest frame. Call :meth:`flush`
    (or :meth:`close`) at the end.

    Args:
        recording: a ``rerun.RecordingStream`` with a sink already set (save, spawn or connect).
        name: the sensor's name in the entity paths (``tactile/<name>/...``).
        grid: (rows, cols) of the readings.
        layout: the board layout (taxel positions), or None for a 5 mm grid.
        batch_frames: frames per column-wise send (1: each frame at once).
        heatmap_every: log the Bz heat map for every this many frames (1: all).
    """

    def __init__(self, recording, *, name: str = "mbts", grid: tuple[int, int] = (4, 4), layout: Any = None,
                 batch_frames: int = 12, heatmap_every: int = 5) -> None:
        if batch_frames < 1 or heatmap_every < 1:
            raise ValueError(f"batch_frames and heatmap_every: expected >= 1, got {batch_frames}, {heatmap_every}")
        self.rr = require_rerun("logging to Rerun")
        self.recording = recording
        self.paths = EntityPaths(name)
        self.origins_mm, self._mask = taxel_origins_mm(grid, layout)
        self.grid = tuple(grid)
        self.batch_frames, self.heatmap_every = batch_frames, heatmap_every
        self._times: list[tuple[float, float, int]] = []
        self._fields: list[np.ndarray] = []
        self._now: tuple[float, float, int] | None = None
        self._t0_sensor: float | None = None
        self._phase: str | None = None
        self.frames = 0
        log_static(self.rr, recording, self.paths, self.origins_mm[self._mask])

    def log_frame(self, field_ut: np.ndarray, *, sensor_time_s: float, host_time_s: float, frame: int) -> None:
        """One (R, C, 3) field in uT at its times (s on the sensor and host clocks, the frame number)."""
        f = np.asarray(field_ut, dtype=np.float32)
        if f.shape != (*self.grid, 3):
            raise ValueError(f"field_ut: expected shape {(*self.grid, 3)}, got {f.shape}")
        self._now = (float(sensor_time_s), float(host_time_s), int(frame))
        self._times.append(self._now)
        self._fields.append(f)
        if len(self._fields) >= self.batch_frames:
            self.flush()

    def sensor_time_s(self, reading) -> float:
        """A reading's ``sensor_time``: its device clock (the host's where the device sends none) from this
        logger's first reading, s."""
        t = reading.t_device_s if math.isfinite(reading.t_device_s) else reading.t_host_s
        if self._t0_sensor is None:
            self._t0_sensor = t
        return t - self._t0_sensor

    def log_reading(self, reading) -> None:
        """A :class:`~tactile_manip.types.TactileReading` at its own times (``frame`` = its sequence number)."""
        self.log_frame(reading.field_ut, sensor_time_s=self.sensor_time_s(reading), host_time_s=reading.t_host_s,
                       frame=reading.seq)

    def flush(self) -> None:
        """Send the buffered fields: arrows column-wise, the heat map of every ``heatmap_every``-th frame."""
        if not self._fields:
            return
        rr, rec = self.rr, self.recording
        times, fields = np.array(self._times), np.stack(self._fields)
        self._times, self._fields = [], []
        n, k = len(fields), int(self._mask.sum())
        indexes = [rr.TimeColumn("sensor_time", duration=times[:, 0]),
                   rr.TimeColumn("frame", sequence=times[:, 2].astype(np.int64))]
        if np.isfinite(times[:, 1]).all():
            indexes.append(rr.TimeColumn("host_time", duration=times[:, 1]))
        rr.send_columns(self.paths.field, indexes=indexes, recording=rec,
                        columns=rr.Arrows3D.columns(vectors=arrows_from_field(fields)[:, self._mask].reshape(-1, 3),
                                                    origins=np.tile(self.origins_mm[self._mask], (n, 1)))
                        .partition([k] * n))
        for i in range(n):
            if (self.frames + i) % self.heatmap_every == 0:
                self._set_time(tuple(times[i]))
                rr.log(self.paths.bz, rr.Tensor(fields[i][..., 2], dim_names=("row", "col")), recording=rec)
        self.frames += n

    def _set_time(self, now: tuple[float, float, int] | None) -> None:
        if now is None:
            return
        rr, rec = self.rr, self.recording
        rr.set_time("sensor_time", duration=float(now[0]), recording=rec)
        rr.set_time("frame", sequence=int(now[2]), recording=rec)
        if math.isfinite(now[1]):
            rr.set_time("host_time", duration=float(now[1]), recording=rec)

    def log_estimate(self, *, angle_rad: float, confidence: float, depth_mm: np.ndarray | None = None) -> None:
        """An angle estimate (rad, in degrees on the plot), its confidence and its depth image (mm), at the time
        of the newest frame."""
        rr, rec = self.rr, self.recording
        self._set_time(self._now)
        if math.isfinite(angle_rad):
            rr.log(self.paths.angle, rr.Scalars(math.degrees(angle_rad)), recording=rec)
        if math.isfinite(confidence):
            rr.log(self.paths.confidence, rr.Scalars(float(confidence)), recording=rec)
        if depth_mm is not None:
            rr.log(self.paths.depth, rr.DepthImage(np.asarray(depth_mm, dtype=np.float32), meter=DEPTH_METER,
                                                   depth_range=DEPTH_RANGE_MM), recording=rec)

    def log_robot(self, *, joints_rad: np.ndarray | None = None, gripper_width_m: float = math.nan,
                  target_angle_rad: float = math.nan, phase: str | None = None) -> None:
        """Arm joints (rad), gripper width (m, plotted in mm), the commanded angle (rad, in deg) and the phase,
        at the time of the newest frame."""
        rr, rec = self.rr, self.recording
        self._set_time(self._now)
        if joints_rad is not None:
            rr.log(JOINTS, rr.Scalars(np.asarray(joints_rad, dtype=np.float64)), recording=rec)
        if math.isfinite(gripper_width_m):
            rr.log(GRIPPER, rr.Scalars(gripper_width_m * 1e3), recording=rec)
        if math.isfinite(target_angle_rad):
            rr.log(TARGET, rr.Scalars(math.degrees(target_angle_rad)), recording=rec)
        if phase is not None and phase != self._phase:
            rr.log(PHASE, rr.TextLog(phase or "(none)"), recording=rec)
            self._phase = phase

    def log_text(self, entity: str, text: str) -> None:
        """A line of text (e.g. a trial's outcome) at the time of the newest frame."""
        self._set_time(self._now)
        self.rr.log(entity, self.rr.TextLog(text), recording=self.recording)

    def log_scalar(self, entity: str, value: float) -> None:
        """One value of a time series at the time of the newest frame."""
        self._set_time(self._now)
        self.rr.log(entity, self.rr.Scalars(float(value)), recording=self.recording)
