"""Episodes as a LeRobotDataset v3.0, written with pyarrow and pandas (the ``lerobot`` package is not needed).

Layout (what ``lerobot.datasets.lerobot_dataset.LeRobotDataset(repo_id, root=OUT)`` reads)::

    OUT/meta/info.json                          codebase_version "v3.0", fps, totals, paths, features
    OUT/meta/stats.json                         per feature: min, max, mean, std, count, q01 q10 q50 q90 q99
    OUT/meta/tasks.parquet                      task_index, indexed by the task string (pandas index)
    OUT/meta/episodes/chunk-000/file-000.parquet  one row per episode: tasks, length, where its frames are, stats
    OUT/meta/tactile.json                       our own: convention, layout, per-episode source facts, calibration
    OUT/data/chunk-000/file-000.parquet         one row per frame (a new file past ``data_files_size_in_mb``)

Features (present when the source has the stream; see docs/lerobot.md for the full table):

- ``observation.tactile.field`` float32 (rows*cols*3,): the baseline-subtracted field, uT, flattened
  ``[row, col, axis]`` and named ``r{row}c{col}_{x|y|z}``; ``observation.tactile.field_raw`` the same before
  the baseline;
- ``observation.state`` float32 (8,): 7 joint positions (rad) and the gripper width (m);
- ``observation.estimate`` float32 (2,): the latest in-hand angle estimate (rad) and its confidence;
- ``action`` float32 (1,): the commanded in-hand angle (rad);
- ``observation.images.tactile_depth`` / ``observation.images.vbts_depth``: depth images (PNG, 3 equal
  channels, one level per 0.01 mm: the dataset's own depth quantum);
- ``next.done`` bool (true on an episode's last frame), ``next.success`` bool (the trial's success, on its
  last frame), ``phase`` int64 (index into ``meta/tactile.json`` "phases"), ``host_time_s`` float64;
- lerobot's own ``timestamp`` (float32, ``frame_index / fps``), ``frame_index``, ``episode_index``, ``index``,
  ``task_index``.

A frame without a value of a stream the dataset has (no estimate yet) holds NaN there.
"""

from __future__ import annotations

import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.interop.frames import PHASES, Episode
from tactile_manip.interop.lerobot_stats import feature_stats

CODEBASE_VERSION = "v3.0"
CHUNKS_SIZE = 1000
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
DEPTH_LEVEL_MM = 0.01  # one PNG level; 255 levels reach 2.55 mm (deeper pixels are clipped)
JOINT_NAMES = tuple(f"joint_{i}_rad" for i in range(1, 8))
DEFAULT_FEATURES = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}


@dataclass(frozen=True)
class _Streams:
    """Which optional streams the dataset carries (a stream is in if any frame of any episode has it)."""

    field_raw: bool
    state: bool
    estimate: bool
    action: bool
    phase: bool
    success: bool
    depth: tuple[int, int] | None        # (H, W) of the reconstructed depth, or None
    vbts_depth: tuple[int, int] | None   # (H, W) of the VBTS depth, or None


def write_lerobot(episodes: list[Episode], out: str | Path, *, ros2: bool = False,
                  source_info: dict[str, Any] | None = None, robot_type: str | None = None) -> dict[str, Any]:
    """Write ``episodes`` as a LeRobotDataset v3.0 in the folder ``out`` (created; must not exist yet).

    Args:
        episodes: on one fps and one taxel grid; indices are renumbered 0, 1, ... in list order.
        out: the dataset folder.
        ros2: ignored (the MCAP writer's option; accepted so every writer has the same signature).
        source_info: facts of the whole source (kind, run config, calibration, header) for ``meta/tactile.json``.
        robot_type: ``info.json``'s robot_type (default "franka_fr3" when the episodes hold joints, else None).

    Returns:
        ``{"episodes", "frames", "tasks", "features", "files", "bytes"}`` of what was written.

    Raises:
        ValueError: no episode, an empty episode, or episodes of different fps or grids.
        FileExistsError: ``out`` exists.
    """
    from tactile_manip.extras import require

    require("pyarrow", "the LeRobot export")
    require("pandas", "the LeRobot export")
    _check(episodes)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=False)
    streams = _streams(episodes)
    grid = episodes[0].grid
    fps = episodes[0].fps
    features = _features(grid, streams)
    tasks = list(dict.fromkeys(e.task for e in episodes))
    columns = [_episode_columns(i, e, tasks.index(e.task), streams, offset)
               for i, e, offset in _with_offsets(episodes)]
    data_files = _write_data(out, columns, features)
    episode_stats = [feature_stats(c, features) for c in columns]
    stats = feature_stats(_concat(columns, features), features)
    _write_episodes(out, episodes, tasks, data_files, episode_stats)
    _write_tasks(out, tasks)
    total = sum(len(e.frames) for e in episodes)
    info = {"codebase_version": CODEBASE_VERSION,
            "robot_type": robot_type if robot_type is not None else ("franka_fr3" if streams.state else None),
            "total_episodes": len(episodes), "total_frames": total, "total_tasks": len(tasks),
            "chunks_size": CHUNKS_SIZE, "data_files_size_in_mb": DATA_FILES_SIZE_IN_MB,
            "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB, "fps": int(fps) if float(fps).is_integer() else fps,
            "splits": {"train": f"0:{len(episodes)}"}, "data_path": DATA_PATH, "video_path": None,
            "features": features}
    _write_json(out / "meta" / "info.json", info)
    _write_json(out / "meta" / "stats.json", _jsonable(stats))
    _write_json(out / "meta" / "tactile.json", _tactile_meta(episodes, grid, streams, source_info))
    files = sorted(p for p in out.rglob("*") if p.is_file())
    return {"episodes": len(episodes), "frames": total, "tasks": len(tasks), "features": sorted(features),
            "files": [str(p.relative_to(out)) for p in files], "bytes": sum(p.stat().st_size for p in files)}


# ---------------------------------------------------------------------------------------------- schema

def _check(episodes: list[Episode]) -> None:
    if not episodes:
        raise ValueError("no episode to write")
    for e in episodes:
        if not e.frames:
            raise ValueError(f"episode {e.index} ({e.task!r}) has no frame")
    rates = sorted({e.fps for e in episodes})
    if len(rates) > 1:
        raise ValueError(f"a LeRobot dataset has one fps; the episodes have {rates} Hz: export them apart")
    grids = sorted({e.grid for e in episodes})
    if len(grids) > 1:
        raise ValueError(f"the episodes mix taxel grids {grids}: export each sensor apart")


def _streams(episodes: list[Episode]) -> _Streams:
    frames = [f for e in episodes for f in e.frames]

    def shape_of(attr: str) -> tuple[int, int] | None:
        shapes = {getattr(f, attr).shape for f in frames if getattr(f, attr) is not None}
        if len(shapes) > 1:
            raise ValueError(f"{attr}: the frames mix image shapes {sorted(shapes)}")
        return tuple(int(n) for n in shapes.pop()) if shapes else None

    return _Streams(
        field_raw=all(f.field_raw_ut is not None for f in frames),
        state=any(f.joints_rad is not None or math.isfinite(f.gripper_width_m) for f in frames),
        estimate=any(math.isfinite(f.angle_rad) or math.isfinite(f.confidence) for f in frames),
        action=any(math.isfinite(f.target_angle_rad) for f in frames),
        phase=any(f.phase for f in frames),
        success=any(e.success is not None for e in episodes),
        depth=shape_of("depth_mm"), vbts_depth=shape_of("vbts_depth_mm"))


def field_names(grid: tuple[int, int]) -> list[str]:
    """``r{row}c{col}_{axis}`` for the flattened ``[row, col, axis]`` field of a ``grid`` board."""
    rows, cols = grid
    return [f"r{r}c{c}_{a}" for r in range(rows) for c in range(cols) for a in "xyz"]


def _features(grid: tuple[int, int], s: _Streams) -> dict[str, dict]:
    n = grid[0] * grid[1] * 3
    features = {"observation.tactile.field": {"dtype": "float32", "shape": [n], "names": field_names(grid)}}
    if s.field_raw:
        features["observation.tactile.field_raw"] = {"dtype": "float32", "shape": [n], "names": field_names(grid)}
    if s.state:
        features["observation.state"] = {"dtype": "float32", "shape": [8],
                                         "names": [*JOINT_NAMES, "gripper_width_m"]}
    if s.estimate:
        features["observation.estimate"] = {"dtype": "float32", "shape": [2], "names": ["angle_rad", "confidence"]}
    for key, hw in (("observation.images.tactile_depth", s.depth), ("observation.images.vbts_depth", s.vbts_depth)):
        if hw is not None:
            features[key] = {"dtype": "image", "shape": [hw[0], hw[1], 3], "names": ["height", "width", "channels"]}
    if s.action:
        features["action"] = {"dtype": "float32", "shape": [1], "names": ["target_angle_rad"]}
    features["next.done"] = {"dtype": "bool", "shape": [1], "names": None}
    if s.success:
        features["next.success"] = {"dtype": "bool", "shape": [1], "names": None}
    if s.phase:
        features["phase"] = {"dtype": "int64", "shape": [1], "names": None}
    features["host_time_s"] = {"dtype": "float64", "shape": [1], "names": None}
    return {**features, **DEFAULT_FEATURES}


def _hf_feature(ft: dict) -> dict:
    """The Hugging Face ``datasets`` feature of a LeRobot feature (kept in the parquet schema's metadata)."""
    if ft["dtype"] == "image":
        return {"_type": "Image"}
    if ft["shape"] == [1]:
        return {"dtype": ft["dtype"], "_type": "Value"}
    return {"feature": {"dtype": ft["dtype"], "_type": "Value"}, "length": ft["shape"][0], "_type": "Sequence"}


def _arrow_type(ft: dict):
    import pyarrow as pa

    if ft["dtype"] == "image":
        return pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    scalar = {"float32": pa.float32(), "float64": pa.float64(), "int64": pa.int64(), "bool": pa.bool_()}[ft["dtype"]]
    return scalar if ft["shape"] == [1] else pa.list_(scalar, ft["shape"][0])


def _schema(features: dict[str, dict]):
    import pyarrow as pa

    hf = {"info": {"features": {k: _hf_feature(ft) for k, ft in features.items()}}}
    return pa.schema([(k, _arrow_type(ft)) for k, ft in features.items()],
                     metadata={b"huggingface": json.dumps(hf).encode()})


# ---------------------------------------------------------------------------------------------- columns

def _with_offsets(episodes: list[Episode]):
    offset = 0
    for i, e in enumerate(episodes):
        yield i, e, offset
        offset += len(e.frames)


def _episode_columns(index: int, e: Episode, task_index: int, s: _Streams, offset: int) -> dict[str, Any]:
    """One episode as numpy columns (image columns: lists of PNG bytes)."""
    frames = e.frames
    n = len(frames)
    cols: dict[str, Any] = {
        "observation.tactile.field": np.stack([f.field_ut.reshape(-1) for f in frames]).astype(np.float32)}
    if s.field_raw:
        cols["observation.tactile.field_raw"] = np.stack([f.field_raw_ut.reshape(-1) for f in frames]).astype(np.float32)
    if s.state:
        joints = np.stack([np.full(7, np.nan) if f.joints_rad is None else np.asarray(f.joints_rad, float).reshape(7)
                           for f in frames])
        width = np.array([f.gripper_width_m for f in frames], np.float64)[:, None]
        cols["observation.state"] = np.hstack([joints, width]).astype(np.float32)
    if s.estimate:
        cols["observation.estimate"] = np.array([[f.angle_rad, f.confidence] for f in frames], np.float32)
    if s.depth is not None:
        cols["observation.images.tactile_depth"] = [_png(f.depth_mm) for f in frames]
    if s.vbts_depth is not None:
        cols["observation.images.vbts_depth"] = [_png(f.vbts_depth_mm) for f in frames]
    if s.action:
        cols["action"] = np.array([[f.target_angle_rad] for f in frames], np.float32)
    done = np.zeros(n, bool)
    done[-1] = True
    cols["next.done"] = done
    if s.success:
        cols["next.success"] = done & bool(e.success)
    if s.phase:
        cols["phase"] = np.array([PHASES.index(f.phase) for f in frames], np.int64)
    cols["host_time_s"] = np.array([f.host_time_s for f in frames], np.float64)
    frame_index = np.arange(n, dtype=np.int64)
    cols["timestamp"] = (frame_index / e.fps).astype(np.float32)
    cols["frame_index"] = frame_index
    cols["episode_index"] = np.full(n, index, np.int64)
    cols["index"] = offset + frame_index
    cols["task_index"] = np.full(n, task_index, np.int64)
    return cols


def _png(depth_mm: np.ndarray | None) -> bytes | None:
    """A depth image as PNG bytes: 3 equal 8-bit channels, one level per DEPTH_LEVEL_MM (None stays None)."""
    if depth_mm is None:
        return None
    from PIL import Image

    levels = np.clip(np.rint(np.asarray(depth_mm, np.float64) / DEPTH_LEVEL_MM), 0, 255).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(np.repeat(levels[:, :, None], 3, axis=2), mode="RGB").save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def _table(cols: dict[str, Any], features: dict[str, dict]):
    import pyarrow as pa

    arrays = []
    for key, ft in features.items():
        values, kind = cols[key], _arrow_type(ft)
        if ft["dtype"] == "image":
            arrays.append(pa.StructArray.from_arrays([pa.array(values, pa.binary()), pa.nulls(len(values), pa.string())],
                                                     fields=list(kind)))
        elif ft["shape"] == [1]:
            arrays.append(pa.array(np.asarray(values).reshape(-1), kind))
        else:
            flat = pa.array(np.ascontiguousarray(values).reshape(-1), kind.value_type)
            arrays.append(pa.FixedSizeListArray.from_arrays(flat, ft["shape"][0]))
    return pa.Table.from_arrays(arrays, schema=_schema(features))


def _concat(columns: list[dict[str, Any]], features: dict[str, dict]) -> dict[str, Any]:
    out = {}
    for key, ft in features.items():
        if ft["dtype"] == "image":
            out[key] = [b for c in columns for b in c[key]]
        else:
            out[key] = np.concatenate([c[key] for c in columns])
    return out


# ---------------------------------------------------------------------------------------------- files

def _write_data(out: Path, columns: list[dict[str, Any]], features: dict[str, dict]) -> list[tuple[int, int]]:
    """Write the frames, a new file once one passes DATA_FILES_SIZE_IN_MB; returns (chunk, file) per episode."""
    import pyarrow.parquet as pq

    where, writer, chunk, file, size = [], None, 0, 0, 0
    schema = _schema(features)
    try:
        for cols in columns:
            table = _table(cols, features)
            if writer is not None and size + table.nbytes > DATA_FILES_SIZE_IN_MB * 1024 * 1024:
                writer.close()
                writer, size = None, 0
                chunk, file = (chunk + 1, 0) if file == CHUNKS_SIZE - 1 else (chunk, file + 1)
            if writer is None:
                path = out / DATA_PATH.format(chunk_index=chunk, file_index=file)
                path.parent.mkdir(parents=True, exist_ok=True)
                writer = pq.ParquetWriter(path, schema=schema, compression="snappy")
            writer.write_table(table)
            size += table.nbytes
            where.append((chunk, file))
    finally:
        if writer is not None:
            writer.close()
    return where


def _write_episodes(out: Path, episodes: list[Episode], tasks: list[str], where: list[tuple[int, int]],
                    episode_stats: list[dict[str, dict[str, np.ndarray]]]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows: dict[str, list] = {"episode_index": [], "tasks": [], "length": [], "data/chunk_index": [],
                             "data/file_index": [], "dataset_from_index": [], "dataset_to_index": []}
    start = 0
    for i, (e, (chunk, file)) in enumerate(zip(episodes, where)):
        n = len(e.frames)
        for key, value in (("episode_index", i), ("tasks", [e.task]), ("length", n), ("data/chunk_index", chunk),
                           ("data/file_index", file), ("dataset_from_index", start), ("dataset_to_index", start + n)):
            rows[key].append(value)
        start += n
    for stats in episode_stats:  # every episode has the same features, so the same stats columns
        for key, value in _flatten({"stats": stats}).items():
            rows.setdefault(key, []).append(np.asarray(value).tolist())
    rows["meta/episodes/chunk_index"] = [0] * len(episodes)
    rows["meta/episodes/file_index"] = [0] * len(episodes)
    path = out / EPISODES_PATH.format(chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.Table.from_pydict(rows), path, compression="snappy")


def _write_tasks(out: Path, tasks: list[str]) -> None:
    import pandas as pd

    frame = pd.DataFrame({"task_index": np.arange(len(tasks), dtype=np.int64)}, index=tasks)
    frame.to_parquet(out / "meta" / "tasks.parquet")  # the task strings are the index, kept by pandas


def _write_json(path: Path, obj: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj, indent=4, allow_nan=False) + "\n", encoding="utf-8")


def _flatten(d: dict, prefix: str = "") -> dict[str, Any]:
    out = {}
    for k, v in d.items():
        key = f"{prefix}/{k}" if prefix else k
        out.update(_flatten(v, key) if isinstance(v, dict) else {key: v})
    return out


def _jsonable(stats: dict[str, dict[str, np.ndarray]]) -> dict[str, dict[str, list]]:
    return {k: {s: np.asarray(v).tolist() for s, v in ft.items()} for k, ft in stats.items()}


# ---------------------------------------------------------------------------------------------- our metadata

def _tactile_meta(episodes: list[Episode], grid: tuple[int, int], s: _Streams,
                  source_info: dict[str, Any] | None) -> dict[str, Any]:
    from tactile_manip.logs.framed_file import json_default
    from tactile_manip.version import code_version

    layout_name = next((e.meta.get("layout") for e in episodes if e.meta.get("layout")), None)
    layout = {"name": layout_name, "grid": list(grid),
              "field": "observation.tactile.field[i] = field_ut[row, col, axis] with i = (row * cols + col) * 3 + axis",
              "axes": "x, y, z of the pad frame; row 0 at +y, column 0 at -x", "unit": "uT"}
    if layout_name:
        try:
            from tactile_manip.boards import load_board

            layout["pitch_mm"] = load_board(layout_name).pitch_mm
        except ValueError:
            pass
    meta = {"format": "tactile_manip.lerobot", "format_version": 1, "code_version": code_version(),
            "convention": "one episode per trial and method (or per recording, or per object of a pair log); frames "
                          "on the sensor clock: timestamp = frame_index / fps, host_time_s = the host's clock",
            "layout": layout, "phases": list(PHASES),
            "depth": {"unit_per_level_mm": DEPTH_LEVEL_MM, "channels": "3 equal channels",
                      "max_mm": 255 * DEPTH_LEVEL_MM} if (s.depth or s.vbts_depth) else None,
            "units": {"observation.state": "rad (joints), m (gripper width)", "observation.estimate": "rad, [0, 1]",
                      "action": "rad", "host_time_s": "s (host clock; time.monotonic() for live sources)"},
            "source": source_info or {},
            "episodes": [{"episode_index": i, "task": e.task, "success": e.success, "frames": len(e.frames), **e.meta}
                         for i, e in enumerate(episodes)]}
    return _finite(json.loads(json.dumps(meta, default=json_default)))


def _finite(obj: Any) -> Any:
    """``obj`` with NaN and infinities as None (strict JSON has no NaN)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite(v) for v in obj]
    return obj
