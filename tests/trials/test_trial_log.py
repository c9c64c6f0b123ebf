"""The trial log: round trip, nothing lost when the writer is killed, torn tails, corrupt lines, resuming."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import warnings
from dataclasses import dataclass
from pathlib import Path

import pytest

from tactile_manip.trials.log import (
    TrialLog,
    TrialLogError,
    TruncatedRecordWarning,
    completed_keys,
    config_hash,
    read_run_info,
    read_trials,
)
from tactile_manip.trials.record import TrialRecord

CONFIG = {"scene": "reorient_sim", "tolerance_deg": 5.0, "methods": ["supermag", "bilinear"]}
CHILD_TIMEOUT_S = 60.0  # interpreter start on a loaded 2-core machine


def make_record(trial: int, method: str = "supermag") -> TrialRecord:
    return TrialRecord(trial=trial, seed=100 + trial, method=method, object="allen_key", true_angle_rad=0.4,
                       offset_mm=(1.25, -0.5), target_angle_rad=0.0, estimated_angle_rad=0.38, confidence=0.7,
                       defined=True, final_angle_rad=0.02, error_rad=0.02, outcome="done",
                       timings_s={"grasp": 1.5, "estimate": 0.003}, extra={"note": "é"})


def write_run(run_dir: Path, n: int, **kwargs) -> list[TrialRecord]:
    recs = [make_record(i) for i in range(n)]
    with TrialLog(run_dir, config=CONFIG, code_version="test", **kwargs) as log:
        for r in recs:
            log.append(r)
    return recs


def test_round_trip_and_run_json(tmp_path):
    recs = write_run(tmp_path / "run", 4)
    assert read_trials(tmp_path / "run") == recs
    assert read_trials(tmp_path / "run" / "trials.jsonl") == recs
    lines = (tmp_path / "run" / "trials.jsonl").read_text(encoding="utf-8").splitlines()
    assert len(lines) == 4 and all(json.loads(x)["method"] == "supermag" for x in lines)
    info = read_run_info(tmp_path / "run")
    assert info["config_hash"] == config_hash(CONFIG) and info["config"] == CONFIG
    assert info["code_version"] == "test" and info["run_id"] and info["resumes"] == []


def test_config_hash_ignores_key_order_and_reads_dataclasses():
    @dataclass
    class Cfg:
        path: Path
        tolerance_deg: float

    assert config_hash({"a": 1, "b": [1, 2]}) == config_hash({"b": (1, 2), "a": 1})
    assert config_hash(Cfg(Path("x.onnx"), 5.0)) == config_hash({"path": "x.onnx", "tolerance_deg": 5.0})
    with pytest.raises(ValueError, match="JSON"):
        config_hash({"x": float("nan")})


_CHILD = textwrap.dedent("""
    import sys
    from tactile_manip.trials.log import TrialLog
    from tactile_manip.trials.record import TrialRecord

    run_dir, n = sys.argv[1], int(sys.argv[2])
    with TrialLog(run_dir, config={"child": True}, code_version="test") as log:
        i = 0
        while n < 0 or i < n:
            log.append(TrialRecord(trial=i, seed=i, method="supermag", object="allen_key", true_angle_rad=0.1,
                                   offset_mm=(0.0, 0.0), target_angle_rad=0.0, final_angle_rad=0.01,
                                   error_rad=0.01, outcome="done", detail="x" * 2000))
            print(i, flush=True)
            i += 1
        sys.stdin.read()  # wait to be killed
""")


def _run_child_until(run_dir: Path, n: int, lines_before_kill: int) -> int:
    """Start a writer process, SIGKILL it after it reported ``lines_before_kill`` appends; return that count."""
    with subprocess.Popen([sys.executable, "-c", _CHILD, str(run_dir), str(n)], stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        watchdog = threading.Timer(CHILD_TIMEOUT_S, proc.kill)
        watchdog.start()
        try:
            reported = 0
            while reported < lines_before_kill and proc.stdout.readline():
                reported += 1
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
        finally:
            watchdog.cancel()
        assert proc.returncode == -signal.SIGKILL, proc.stderr.read()
    return reported


def test_records_survive_sigkill_of_the_writer(tmp_path):
    assert _run_child_until(tmp_path / "run", 7, 7) == 7
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no torn line: the writer was idle when killed
        recs = read_trials(tmp_path / "run")
    assert [r.trial for r in recs] == list(range(7))
    assert completed_keys(tmp_path / "run") == {(i, "supermag") for i in range(7)}


def test_kill_mid_stream_loses_no_reported_record_and_resumes(tmp_path):
    reported = _run_child_until(tmp_path / "run", -1, 40)  # the writer keeps appending when killed
    assert reported == 40
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TruncatedRecordWarning)
        recs = read_trials(tmp_path / "run")
    assert [r.trial for r in recs] == list(range(len(recs))) and len(recs) >= reported
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TruncatedRecordWarning)
        with TrialLog(tmp_path / "run", config={"child": True}, resume=True, code_version="test") as log:
            log.append(make_record(10_000))
    assert read_trials(tmp_path / "run")[-1].trial == 10_000


def test_truncated_last_line_is_skipped_with_a_warning(tmp_path):
    write_run(tmp_path / "run", 3)
    file = tmp_path / "run" / "trials.jsonl"
    with open(file, "ab") as f:
        f.write(json.dumps(make_record(3).to_dict()).encode()[:57])  # killed mid-write
    with pytest.warns(TruncatedRecordWarning, match=r"trials.jsonl:4"):
        assert len(read_trials(file)) == 3
    assert completed_keys(file) == {(0, "supermag"), (1, "supermag"), (2, "supermag")}


def test_resume_cuts_the_torn_tail_and_appends_on_a_fresh_line(tmp_path):
    write_run(tmp_path / "run", 3)
    file = tmp_path / "run" / "trials.jsonl"
    with open(file, "ab") as f:
        f.write(b'{"trial": 3, "seed"')
    with pytest.warns(TruncatedRecordWarning, match="removed an incomplete last record"):
        with TrialLog(tmp_path / "run", config=CONFIG, resume=True, code_version="v2") as log:
            assert log.completed == {(i, "supermag") for i in range(3)}
            log.append(make_record(3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert [r.trial for r in read_trials(file)] == [0, 1, 2, 3]
    info = read_run_info(tmp_path / "run")
    assert info["code_version"] == "test" and [r["code_version"] for r in info["resumes"]] == ["v2"]


def test_complete_last_record_without_newline_is_kept(tmp_path):
    write_run(tmp_path / "run", 2)
    file = tmp_path / "run" / "trials.jsonl"
    file.write_bytes(file.read_bytes().rstrip(b"\n"))
    assert len(read_trials(file)) == 2
    with TrialLog(tmp_path / "run", config=CONFIG, resume=True, code_version="test") as log:
        log.append(make_record(2))
    assert [r.trial for r in read_trials(file)] == [0, 1, 2]


@pytest.mark.parametrize("bad_line, reason", [
    (b'{"trial": 1, "seed', "not a JSON line"),
    (b'{"trial": 1, "colour": "red"}', "not a valid trial record"),
    (b'[1, 2]', "expected a JSON object"),
    (json.dumps({**make_record(1).to_dict(), "version": 99}).encode(), "trial record version 99 is newer"),
], ids=["torn", "unknown_field", "not_an_object", "newer_version"])
def test_corrupt_line_in_the_middle_raises_with_its_line_number(tmp_path, bad_line, reason):
    write_run(tmp_path / "run", 3)
    file = tmp_path / "run" / "trials.jsonl"
    lines = file.read_bytes().splitlines()
    file.write_bytes(b"\n".join([lines[0], bad_line, lines[2]]) + b"\n")
    with pytest.raises(TrialLogError, match=rf"trials.jsonl:2: {reason}"):
        read_trials(file)


def test_empty_log_and_missing_paths(tmp_path):
    with TrialLog(tmp_path / "run", config=CONFIG, code_version="test"):
        pass
    assert read_trials(tmp_path / "run") == []
    assert completed_keys(tmp_path / "run") == set()
    assert completed_keys(tmp_path / "nowhere") == set()
    with pytest.raises(TrialLogError, match="no run directory or trial log"):
        read_trials(tmp_path / "nowhere")
    (tmp_path / "empty_dir").mkdir()
    with pytest.raises(TrialLogError, match="holds no trials.jsonl"):
        read_trials(tmp_path / "empty_dir")


def test_existing_run_is_not_appended_to_without_resume(tmp_path):
    write_run(tmp_path / "run", 2)
    with pytest.raises(TrialLogError, match="already holds run"):
        TrialLog(tmp_path / "run", config=CONFIG, code_version="test").open()
    with pytest.raises(TrialLogError, match="another config") as info:
        TrialLog(tmp_path / "run", config={**CONFIG, "tolerance_deg": 10.0}, resume=True,
                 code_version="test").open()
    assert f"tolerance_deg: {CONFIG['tolerance_deg']!r} -> 10.0" in str(info.value)  # names what differs
    assert len(read_trials(tmp_path / "run")) == 2


def test_resume_skips_nothing_twice(tmp_path):
    write_run(tmp_path / "run", 2)
    with TrialLog(tmp_path / "run", config=CONFIG, resume=True, code_version="test") as log:
        assert log.completed == completed_keys(tmp_path / "run") == {(0, "supermag"), (1, "supermag")}
        with pytest.raises(TrialLogError, match="already in"):
            log.append(make_record(1))
        log.append(make_record(1, "bilinear"))
    assert [(r.trial, r.method) for r in read_trials(tmp_path / "run")] == [
        (0, "supermag"), (1, "supermag"), (1, "bilinear")]


def test_log_without_run_json_is_refused(tmp_path):
    write_run(tmp_path / "run", 1)
    (tmp_path / "run" / "run.json").unlink()
    with pytest.raises(TrialLogError, match="without run.json"):
        TrialLog(tmp_path / "run", config=CONFIG, resume=True, code_version="test").open()


def test_a_second_writer_is_refused_while_the_first_holds_the_log(tmp_path):
    with TrialLog(tmp_path / "run", config=CONFIG, code_version="test") as first:
        first.append(make_record(0))
        with pytest.raises(TrialLogError, match="another process"):
            TrialLog(tmp_path / "run", config=CONFIG, resume=True, code_version="test").open()
        first.append(make_record(1))
    assert len(read_trials(tmp_path / "run")) == 2


def test_append_needs_an_open_log(tmp_path):
    log = TrialLog(tmp_path / "run", config=CONFIG, code_version="test")
    assert not (tmp_path / "run").exists()  # the constructor does no I/O
    with pytest.raises(TrialLogError, match="not open"):
        log.append(make_record(0))


def test_numpy_values_are_logged_as_plain_json_and_other_objects_refused(tmp_path):
    import numpy as np

    rec = make_record(0)
    rec.extra = {"gain": np.float32(0.5), "pose": np.eye(2)}
    with TrialLog(tmp_path / "run", config=CONFIG, code_version="test") as log:
        log.append(rec)
        bad = make_record(1)
        bad.extra = {"x": object()}
        with pytest.raises(TrialLogError, match="trial 1 of method 'supermag' cannot be logged"):
            log.append(bad)
    assert read_trials(tmp_path / "run")[0].extra == {"gain": 0.5, "pose": [[1.0, 0.0], [0.0, 1.0]]}
