"""Episodes to a ``.rrd`` file (``tactile-manip export SOURCE --format rrd``), column-wise with ``send_columns``.

One recording holds every episode on the entity paths of :mod:`tactile_manip.interop.rerun_log`. The
``episode_time`` timeline restarts at each episode's first frame (plots of several episodes overlay on it);
``sensor_time`` runs on across the export: an episode starts where the host clock says it did relative to the
first (gaps between trials are kept), and never before the previous one ended. ``frame`` is the row index
over the export and ``host_time`` the host clock of each frame (episodes that lack it do not log it).
The Bz heat map is a Tensor, which ``send_columns`` cannot batch: it is logged row by row.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.interop.frames import Episode, Frame
from tactile_manip.interop.rerun_log import (
    APPLICATION_ID, DEPTH_METER, DEPTH_RANGE_MM, EPISODE, GRIPPER, JOINTS, PHASE, TARGET, VBTS_DEPTH, EntityPaths,
    arrows_from_field, blueprint, log_static, require_rerun, taxel_origins_mm,
)
from tactile_manip.interop.timeline import check_exportable, episode_starts_s, layout_of


def write_rrd(episodes: list[Episode], out: Path, *, ros2: bool = False) -> dict[str, Any]:
    """Write ``episodes`` to the Rerun file ``out`` (``ros2`` is ignored: it concerns MCAP).

    Returns:
        ``{"frames": n, "episodes": k, "entities": [...], "rerun_sdk": version}``.

    Raises:
        ValueError: no episodes, or episodes of different taxel grids or sensor names.
    """
    del ros2
    rr = require_rerun("export --format rrd")
    episodes, name = check_exportable(episodes)
    paths = EntityPaths(name)
    rec = rr.RecordingStream(APPLICATION_ID)
    frames = [f for e in episodes for f in e.frames]
    vbts = any(f.vbts_depth_mm is not None for f in frames)
    robot = any(f.joints_rad is not None or math.isfinite(f.gripper_width_m) or f.phase for f in frames)
    rr.save(str(out), default_blueprint=blueprint(paths, robot=robot, vbts=vbts), recording=rec)
    origins, mask = taxel_origins_mm(episodes[0].grid, layout_of(episodes[0]))
    entities: set[str] = set()
    log_static(rr, rec, paths, origins[mask])
    row = 0
    for episode, start in zip(episodes, episode_starts_s(episodes)):
        entities |= _write_episode(rr, rec, paths, episode, start_s=start, first_row=row, origins=origins, mask=mask)
        row += len(episode.frames)
    rec.flush()
    rec.disconnect()
    return {"frames": row, "episodes": len(episodes), "entities": sorted(entities), "rerun_sdk": rr.__version__}


def _times(rr, frames: list[Frame], keep: np.ndarray, *, start_s: float, first_row: int) -> list:
    t = np.array([f.t_s for f in frames])[keep]
    host = np.array([f.host_time_s for f in frames])[keep]
    cols = [rr.TimeColumn("sensor_time", duration=start_s + t), rr.TimeColumn("episode_time", duration=t),
            rr.TimeColumn("frame", sequence=first_row + np.flatnonzero(keep))]
    if np.isfinite(host).all():
        cols.append(rr.TimeColumn("host_time", duration=host))
    return cols


def _write_episode(rr, rec, paths: EntityPaths, episode: Episode, *, start_s: float, first_row: int,
                   origins: np.ndarray, mask: np.ndarray) -> set[str]:
    frames = episode.frames
    n = len(frames)
    every = np.ones(n, bool)
    written = set()

    def send(entity: str, keep: np.ndarray, columns) -> None:
        if keep.any():
            rr.send_columns(entity, indexes=_times(rr, frames, keep, start_s=start_s, first_row=first_row),
                            columns=columns, recording=rec)
            written.add(entity)

    fields = np.stack([f.field_ut for f in frames]).astype(np.float32)          # (N, R, C, 3)
    k = int(mask.sum())
    send(paths.field, every, rr.Arrows3D.columns(vectors=arrows_from_field(fields)[:, mask].reshape(-1, 3),
                                                  origins=np.tile(origins[mask], (n, 1))).partition([k] * n))
    _send_bz(rr, rec, paths, fields, frames, start_s=start_s, first_row=first_row)
    written.add(paths.bz)
    for entity, values in ((paths.angle, np.degrees([f.angle_rad for f in frames])),
                           (paths.confidence, np.array([f.confidence for f in frames], dtype=np.float64)),
                           (GRIPPER, np.array([f.gripper_width_m for f in frames]) * 1e3),
                           (TARGET, np.degrees([f.target_angle_rad for f in frames]))):
        keep = np.isfinite(values)
        send(entity, keep, rr.Scalars.columns(scalars=values[keep]))
    keep = np.array([f.joints_rad is not None for f in frames])
    if keep.any():
        joints = np.stack([np.asarray(f.joints_rad, dtype=np.float64) for f in frames if f.joints_rad is not None])
        send(JOINTS, keep, rr.Scalars.columns(scalars=joints.reshape(-1)).partition([joints.shape[1]] * len(joints)))
    for entity, attr in ((paths.depth, "depth_mm"), (VBTS_DEPTH, "vbts_depth_mm")):
        keep = np.array([getattr(f, attr) is not None for f in frames])
        if keep.any():
            send(entity, keep, _depth_columns(rr, [getattr(f, attr) for f in frames if getattr(f, attr) is not None]))
    phases = [f.phase for f in frames]
    keep = np.array([i == 0 or phases[i] != phases[i - 1] for i in range(n)]) & np.array([p != "" for p in phases])
    send(PHASE, keep, rr.TextLog.columns(text=[p for p, k in zip(phases, keep) if k]))
    outcome = "" if episode.success is None else (": success" if episode.success else ": failure")
    first = np.zeros(n, bool)
    first[0] = True
    send(EPISODE, first, rr.TextLog.columns(text=[f"episode {episode.index}: {episode.task}{outcome}"]))
    return written


def _depth_columns(rr, images: list[np.ndarray]):
    depth = np.stack([np.asarray(d, dtype=np.float32) for d in images])           # (M, H, W) mm
    m, h, w = depth.shape
    fmt = rr.components.ImageFormat(width=w, height=h, channel_datatype="F32")
    return rr.DepthImage.columns(buffer=np.ascontiguousarray(depth).view(np.uint8).reshape(m, -1),
                                 format=[fmt] * m, meter=np.full(m, DEPTH_METER, np.float32),
                                 depth_range=[DEPTH_RANGE_MM] * m)


def _send_bz(rr, rec, paths: EntityPaths, fields: np.ndarray, frames: list[Frame], *, start_s: float,
             first_row: int) -> None:
    has_host = all(math.isfinite(f.host_time_s) for f in frames)
    for i, (f, frame) in enumerate(zip(fields, frames)):
        rr.set_time("sensor_time", duration=start_s + frame.t_s, recording=rec)
        rr.set_time("episode_time", duration=frame.t_s, recording=rec)
        rr.set_time("frame", sequence=first_row + i, recording=rec)
        if has_host:
            rr.set_time("host_time", duration=frame.host_time_s, recording=rec)
        rr.log(paths.bz, rr.Tensor(f[..., 2], dim_names=("row", "col")), recording=rec)
    rec.reset_time()
