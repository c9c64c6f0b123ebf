"""Sources become episodes on the sensor clock; damaged ones give what is intact and say what was skipped."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

from tactile_manip.interop.sources import SourceError, read_source
from tactile_manip.sensors.recording import read_recording
from tactile_manip.trials.frames import frames_path, read_trial_frames
from tactile_manip.trials.log import read_trials

RATE_HZ = 125.0


def test_a_recording_is_one_episode_of_every_frame_with_its_exact_fields_and_host_times(recording) -> None:
    source = read_source(recording)
    rec = read_recording(recording)
    (episode,) = source.episodes
    assert source.kind == "recording" and not source.skipped
    assert episode.fps == RATE_HZ and len(episode.frames) == len(rec) == 1250
    assert episode.success is None and episode.grid == (4, 4)
    fields = np.stack([f.field_ut for f in episode.frames])
    assert fields.dtype == np.float32 and np.array_equal(fields, rec.field_raw_ut())
    assert [f.host_time_s for f in episode.frames] == rec.t_host_s.tolist()
    assert [f.t_s for f in episode.frames] == [k / RATE_HZ for k in range(1250)]
    assert episode.meta["baseline"].startswith("none")


def test_a_trial_run_gives_one_episode_per_trial_and_method_with_task_and_success(trial_run) -> None:
    source = read_source(trial_run)
    records = read_trials(trial_run)
    assert source.kind == "trials" and not source.skipped
    assert len(source.episodes) == len(records) == 9  # 3 trials x the scene's 3 methods
    assert [e.index for e in source.episodes] == list(range(9))
    tolerance = math.radians(5.0)
    for e, r in zip(source.episodes, records):
        frames = read_trial_frames(frames_path(trial_run, r.trial, r.method))
        assert (e.meta["trial"], e.meta["method"]) == (r.trial, r.method)
        assert r.estimated_grip_force_n is not None  # the shipped scene names a contact model
        assert e.meta["estimated_grip_force_n"] == r.estimated_grip_force_n
        assert e.task == f"reorient {r.object} to 0 deg" and e.fps == 125.0
        assert e.success == r.succeeded(tolerance)
        assert len(e.frames) == len(frames)
        assert np.array_equal(np.stack([f.field_ut for f in e.frames]), frames.rows["field_ut"])
        assert e.frames[0].joints_rad.shape == (7,) and e.frames[-1].phase == "release"


def test_a_pair_log_gives_one_episode_per_object_with_its_vbts_depth(pair_log) -> None:
    from tactile_manip.collection.pair_log import read_pair_log

    source = read_source(pair_log)
    log = read_pair_log(pair_log)
    assert [e.task for e in source.episodes] == ["press ball on the sensor pair", "press letter_r on the sensor pair"]
    assert [len(e.frames) for e in source.episodes] == [3, 2]
    balls = [p for p in log.pairs if p.info["object"] == "ball"]
    for frame, pair in zip(source.episodes[0].frames, balls):
        assert np.array_equal(frame.field_ut, pair.field_ut) and np.array_equal(frame.field_raw_ut, pair.field_raw_ut)
        assert np.array_equal(np.rint(frame.vbts_depth_mm / 0.01).astype(np.uint8), pair.depth_q)


def test_a_damaged_trial_run_gives_what_is_intact_and_names_each_loss(trial_run, tmp_path) -> None:
    run = tmp_path / "R"
    shutil.copytree(trial_run, run)
    records = read_trials(run)
    lines = (run / "trials.jsonl").read_bytes().split(b"\n")
    lines[1] = lines[1][:40]  # a damaged line in the middle: trial 0 of the second method
    (run / "trials.jsonl").write_bytes(b"\n".join(lines))
    frames_path(run, records[2].trial, records[2].method).unlink()  # a missing frames file
    torn = frames_path(run, records[3].trial, records[3].method)
    n_torn = len(read_trial_frames(torn))
    torn.write_bytes(torn.read_bytes()[:-5])  # a torn tail
    source = read_source(run)
    assert [(e.meta["trial"], e.meta["method"]) for e in source.episodes] == [
        (r.trial, r.method) for k, r in enumerate(records) if k not in (1, 2)]
    assert len(source.episodes[1].frames) == n_torn - 1  # records[3]: the second episode kept
    text = "\n".join(source.skipped)
    assert len(source.skipped) == 3, text
    assert "trials.jsonl:2: a damaged line" in text and "no frames file" in text and "torn tail" in text


def test_a_recording_with_a_torn_tail_keeps_every_intact_frame(tmp_path, make_recording) -> None:
    path = make_recording(tmp_path / "r.tmrec", seconds=1.0)
    path.write_bytes(path.read_bytes()[:-10])
    source = read_source(path)
    assert len(source.episodes[0].frames) == 124
    assert any("torn tail" in s for s in source.skipped)


def test_what_is_not_a_source_is_refused_with_what_to_give(tmp_path) -> None:
    (tmp_path / "x.txt").write_text("hello")
    with pytest.raises(SourceError, match="not a trial run folder, a recording or a pair log"):
        read_source(tmp_path / "x.txt")
    with pytest.raises(SourceError, match="without trials.jsonl"):
        read_source(tmp_path)
    with pytest.raises(SourceError, match="no such source"):
        read_source(tmp_path / "missing")
    run = tmp_path / "run"
    run.mkdir()
    (run / "trials.jsonl").write_text(json.dumps({"trial": 0}) + "\n")
    with pytest.raises(SourceError, match="nothing to export"):
        read_source(run)
