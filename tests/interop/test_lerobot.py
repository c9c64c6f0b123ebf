"""The LeRobotDataset v3.0 writer: the layout lerobot reads, checked with pyarrow; exact values back."""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow", reason="the LeRobot export needs pyarrow (extra 'lerobot')")
pq = pytest.importorskip("pyarrow.parquet", reason="the LeRobot export needs pyarrow (extra 'lerobot')")
pd = pytest.importorskip("pandas", reason="the LeRobot export needs pandas (extra 'lerobot')")

from tactile_manip.interop.frames import Episode, Frame  # noqa: E402
from tactile_manip.interop.lerobot import field_names, write_lerobot  # noqa: E402
from tactile_manip.interop.sources import read_source  # noqa: E402
from tactile_manip.sensors.recording import read_recording  # noqa: E402

INFO_KEYS = {"codebase_version", "robot_type", "total_episodes", "total_frames", "total_tasks", "chunks_size",
             "data_files_size_in_mb", "video_files_size_in_mb", "fps", "splits", "data_path", "video_path",
             "features"}
EPISODE_COLUMNS = {"episode_index", "tasks", "length", "data/chunk_index", "data/file_index", "dataset_from_index",
                   "dataset_to_index", "meta/episodes/chunk_index", "meta/episodes/file_index"}
STATS = {"min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"}


def _check_layout(root, *, episodes: int, frames: int) -> tuple[dict, pa.Table]:
    """Every file lerobot reads, checked against the v3.0 layout; returns info.json and the data table."""
    info = json.loads((root / "meta" / "info.json").read_text())
    assert set(info) == INFO_KEYS and info["codebase_version"] == "v3.0"
    assert (info["total_episodes"], info["total_frames"]) == (episodes, frames)
    assert info["splits"] == {"train": f"0:{episodes}"} and info["video_path"] is None
    features = info["features"]
    for key in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        assert features[key]["shape"] == [1]
    data = pq.read_table(root / "data" / "chunk-000" / "file-000.parquet")
    assert data.column_names == list(features)
    hf = json.loads(data.schema.metadata[b"huggingface"])["info"]["features"]
    assert set(hf) == set(features)
    for key, ft in features.items():
        kind = data.schema.field(key).type
        if ft["dtype"] == "image":
            assert kind == pa.struct([("bytes", pa.binary()), ("path", pa.string())]) and hf[key] == {"_type": "Image"}
        elif ft["shape"] == [1]:
            assert str(kind) in {"float": "float", "float32": "float", "float64": "double", "int64": "int64",
                                 "bool": "bool"}[ft["dtype"]]
        else:
            assert pa.types.is_fixed_size_list(kind) and kind.list_size == ft["shape"][0]
            assert len(ft["names"]) == ft["shape"][0]
    assert data.num_rows == frames
    assert data.column("index").to_pylist() == list(range(frames))
    ep = pq.read_table(root / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pandas()
    assert EPISODE_COLUMNS <= set(ep.columns) and len(ep) == episodes
    assert ep["dataset_to_index"].iloc[-1] == frames
    assert (ep["dataset_to_index"] - ep["dataset_from_index"] == ep["length"]).all()
    assert {c.split("/")[-1] for c in ep.columns if c.startswith("stats/")} == STATS
    tasks = pd.read_parquet(root / "meta" / "tasks.parquet")
    assert list(tasks.columns) == ["task_index"] and tasks["task_index"].tolist() == list(range(len(tasks)))
    assert info["total_tasks"] == len(tasks)
    stats = json.loads((root / "meta" / "stats.json").read_text())
    assert set(stats) == set(features) and all(set(s) == STATS for s in stats.values())
    return info, data


def test_a_ten_second_recording_exports_every_frame_with_exact_values(recording, tmp_path) -> None:
    source = read_source(recording)
    summary = write_lerobot(source.episodes, tmp_path / "ds")
    rec = read_recording(recording)
    info, data = _check_layout(tmp_path / "ds", episodes=1, frames=1250)
    assert summary["frames"] == 1250 and info["fps"] == 125
    field = np.array(data.column("observation.tactile.field").to_pylist(), np.float32)
    assert np.array_equal(field, rec.field_raw_ut().reshape(1250, 48))
    assert data.column("host_time_s").to_pylist() == rec.t_host_s.tolist()
    assert np.array_equal(data.column("timestamp").to_numpy(), (np.arange(1250) / 125.0).astype(np.float32))
    assert data.column("frame_index").to_pylist() == list(range(1250))
    assert data.column("next.done").to_pylist() == [False] * 1249 + [True]
    assert info["features"]["observation.tactile.field"]["names"] == field_names((4, 4))
    assert "observation.state" not in info["features"] and "next.success" not in info["features"]
    stats = json.loads((tmp_path / "ds" / "meta" / "stats.json").read_text())["observation.tactile.field"]
    assert np.allclose(stats["mean"], field.astype(np.float64).mean(axis=0), rtol=1e-9)
    assert stats["count"] == [1250]


def test_a_trial_run_exports_one_episode_per_trial_and_method_at_the_sensor_rate(trial_run, tmp_path) -> None:
    source = read_source(trial_run)
    write_lerobot(source.episodes, tmp_path / "ds", source_info={"kind": source.kind, **source.meta})
    total = source.frames
    info, data = _check_layout(tmp_path / "ds", episodes=9, frames=total)
    assert info["fps"] == 125 and info["robot_type"] == "franka_fr3"
    features = info["features"]
    assert features["observation.tactile.field"]["shape"] == [48] and features["observation.state"]["shape"] == [8]
    assert features["observation.estimate"]["names"] == ["angle_rad", "confidence"]
    assert features["action"]["names"] == ["target_angle_rad"]
    episode_index = data.column("episode_index").to_numpy()
    done = np.array(data.column("next.done").to_pylist())
    success = np.array(data.column("next.success").to_pylist())
    for e in source.episodes:
        rows = np.flatnonzero(episode_index == e.index)
        assert len(rows) == len(e.frames) and done[rows].tolist() == [False] * (len(rows) - 1) + [True]
        assert success[rows[-1]] == e.success and not success[rows[:-1]].any()
        field = np.array(data.column("observation.tactile.field").take(pa.array(rows)).to_pylist(), np.float32)
        assert np.array_equal(field, np.stack([f.field_ut.reshape(48) for f in e.frames]))
    tasks = pd.read_parquet(tmp_path / "ds" / "meta" / "tasks.parquet")
    assert sorted(tasks.index) == sorted({e.task for e in source.episodes})
    ours = json.loads((tmp_path / "ds" / "meta" / "tactile.json").read_text())
    assert ours["layout"]["grid"] == [4, 4] and ours["source"]["kind"] == "trials"
    assert [(e["trial"], e["method"]) for e in ours["episodes"]] == [(e.meta["trial"], e.meta["method"])
                                                                     for e in source.episodes]


def test_depth_images_are_png_structs_that_decode_to_the_exact_levels(pair_log, tmp_path) -> None:
    from PIL import Image

    source = read_source(pair_log)
    write_lerobot(source.episodes, tmp_path / "ds")
    info, data = _check_layout(tmp_path / "ds", episodes=2, frames=5)
    assert info["features"]["observation.images.vbts_depth"] == {
        "dtype": "image", "shape": [200, 200, 3], "names": ["height", "width", "channels"]}
    images = data.column("observation.images.vbts_depth").to_pylist()
    frames = [f for e in source.episodes for f in e.frames]
    for image, frame in zip(images, frames):
        pixels = np.asarray(Image.open(io.BytesIO(image["bytes"])))
        assert pixels.shape == (200, 200, 3) and image["path"] is None
        assert np.array_equal(pixels[..., 0], np.rint(frame.vbts_depth_mm / 0.01).astype(np.uint8))
    stats = json.loads((tmp_path / "ds" / "meta" / "stats.json").read_text())["observation.images.vbts_depth"]
    assert np.array(stats["max"]).shape == (3, 1, 1) and 0 < stats["max"][0][0][0] <= 1


def test_episodes_that_cannot_share_a_dataset_are_refused(tmp_path) -> None:
    frame = Frame(t_s=0.0, host_time_s=0.0, field_ut=np.zeros((4, 4, 3), np.float32))
    with pytest.raises(ValueError, match="one fps"):
        write_lerobot([Episode(0, "a", 125.0, [frame]), Episode(1, "b", 100.0, [frame])], tmp_path / "a")
    with pytest.raises(ValueError, match="no frame"):
        write_lerobot([Episode(0, "a", 125.0, [])], tmp_path / "b")
    with pytest.raises(ValueError, match="no episode"):
        write_lerobot([], tmp_path / "c")
    assert not any(tmp_path.iterdir())


def test_values_a_frame_lacks_are_nan_and_left_out_of_the_stats(tmp_path) -> None:
    field = np.ones((4, 4, 3), np.float32)
    frames = [Frame(t_s=k / 125, host_time_s=float(k), field_ut=field, target_angle_rad=0.0,
                    angle_rad=math.nan if k < 2 else 0.5, confidence=math.nan if k < 2 else 0.9) for k in range(4)]
    write_lerobot([Episode(0, "t", 125.0, frames)], tmp_path / "ds")
    data = pq.read_table(tmp_path / "ds" / "data" / "chunk-000" / "file-000.parquet")
    estimate = np.array(data.column("observation.estimate").to_pylist())
    assert np.isnan(estimate[:2]).all() and np.allclose(estimate[2:], [0.5, 0.9])
    stats = json.loads((tmp_path / "ds" / "meta" / "stats.json").read_text())["observation.estimate"]
    assert np.allclose(stats["mean"], [0.5, 0.9]) and stats["count"] == [4]


def test_lerobot_itself_loads_the_dataset_and_reads_every_frame(trial_run, tmp_path) -> None:
    pytest.importorskip("lerobot", reason="lerobot is not installed here (benchmarks/check_lerobot_load.py runs "
                                          "the same check in its own environment)")
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    source = read_source(trial_run)
    write_lerobot(source.episodes, tmp_path / "ds")
    ds = LeRobotDataset(repo_id="local/tactile", root=tmp_path / "ds")
    assert ds.num_episodes == 9 and ds.fps == 125 and len(ds) == source.frames
    frames = [f for e in source.episodes for f in e.frames]
    for i in range(len(ds)):
        item = ds[i]
        assert tuple(item["observation.tactile.field"].shape) == (48,)
        assert np.array_equal(item["observation.tactile.field"].numpy(), frames[i].field_ut.reshape(48))


def test_frames_roll_over_to_new_files_past_the_size_limit(trial_run, tmp_path, monkeypatch) -> None:
    from tactile_manip.interop import lerobot

    monkeypatch.setattr(lerobot, "DATA_FILES_SIZE_IN_MB", 0)  # every episode past the first opens a new file
    source = read_source(trial_run)
    write_lerobot(source.episodes, tmp_path / "ds")
    files = sorted((tmp_path / "ds" / "data" / "chunk-000").glob("*.parquet"))
    assert [f.name for f in files] == [f"file-{i:03d}.parquet" for i in range(9)]
    episodes = pq.read_table(tmp_path / "ds" / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pandas()
    assert episodes["data/file_index"].tolist() == list(range(9))
    for row, f in zip(episodes.itertuples(), files):
        table = pq.read_table(f)
        assert table.column("index").to_pylist() == list(range(row.dataset_from_index, row.dataset_to_index))
