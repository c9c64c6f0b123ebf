"""Where each episode sits in time and which sensor it shows: shared by the Rerun and MCAP writers.

An export lays its episodes on one clock: each starts where the host clock says it did relative to the
first episode (so the gaps between trials are kept), never before the previous one ended; within an
episode frames keep their sensor-clock times ``t_s``. This module imports numpy only.
"""

from __future__ import annotations

import math

from tactile_manip.interop.frames import Episode

DEFAULT_SENSOR_NAME = "mbts"


def sensor_name(episode: Episode) -> str:
    """The tactile sensor's name in entity paths and topics: ``meta["sensor_name"]`` or ``"mbts"``."""
    name = episode.meta.get("sensor_name", DEFAULT_SENSOR_NAME)
    return name if isinstance(name, str) and name else DEFAULT_SENSOR_NAME


def layout_of(episode: Episode):
    """The board layout named in ``meta["layout"]`` when it matches the frames' grid, else None."""
    from tactile_manip.boards import board_names, load_board

    name = str(episode.meta.get("layout", ""))
    layout = load_board(name) if name in board_names() else None
    return layout if layout is not None and tuple(layout.grid) == episode.grid else None


def check_exportable(episodes: list[Episode]) -> tuple[list[Episode], str]:
    """The episodes that have frames and their one sensor name.

    Raises:
        ValueError: no episode has frames, or they mix taxel grids or sensor names.
    """
    kept = [e for e in episodes if e.frames]
    if not kept:
        raise ValueError("nothing to export: no episode has frames")
    grids = {e.grid for e in kept}
    names = {sensor_name(e) for e in kept}
    if len(grids) > 1 or len(names) > 1:
        raise ValueError(f"episodes of one export must share a sensor: grids {sorted(grids)}, names {sorted(names)}")
    return kept, names.pop()


def episode_starts_s(episodes: list[Episode]) -> list[float]:
    """Each episode's start on the export's clock, s from the first episode's first frame."""
    starts, end = [], -math.inf
    host0 = next((e.frames[0].host_time_s for e in episodes if e.frames and math.isfinite(e.frames[0].host_time_s)),
                 math.nan)
    for e in episodes:
        if not e.frames:
            starts.append(max(end, 0.0))
            continue
        gap = e.frames[0].host_time_s - host0
        start = gap if math.isfinite(gap) else 0.0
        start = max(start, end + 1.0 / e.fps) if math.isfinite(end) else max(start, 0.0)
        starts.append(start)
        end = start + e.frames[-1].t_s
    return starts


def first_host_time_s(episodes: list[Episode]) -> float:
    """The first finite host time of the first frames, s, or 0.0 when no episode has one."""
    return next((e.frames[0].host_time_s for e in episodes if e.frames and math.isfinite(e.frames[0].host_time_s)),
                0.0)
