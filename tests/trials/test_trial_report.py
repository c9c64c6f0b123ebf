"""The report files and figures, and ``tactile-manip score`` end to end on a run directory built here."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from checks import assert_one_line_error

from tactile_manip.cli import main
from tactile_manip.trials.log import TrialLog
from tactile_manip.trials.record import TrialRecord
from tactile_manip.trials.report import tolerance_tag, write_report

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
OBJECTS = ("allen_key",) * 3 + ("letter_r",) * 3
# (outcome, signed error in deg): at 5 deg supermag 5/6, bilinear 1/6; at 10 deg supermag 6/6
SUPERMAG = [("done", 1.0), ("done", -2.0), ("done", 3.0), ("done", 4.5), ("done", -7.0), ("done", 0.5)]
BILINEAR = [("done", 12.0), ("abstained", None), ("done", -4.0), ("grasp_failed", None), ("done", 30.0),
            ("ik_failed", None)]


def paired_run() -> list[TrialRecord]:
    recs = []
    for method, rows in (("supermag", SUPERMAG), ("bilinear", BILINEAR)):
        for i, (outcome, error_deg) in enumerate(rows):
            error = None if error_deg is None else math.radians(error_deg)
            recs.append(TrialRecord(trial=i, seed=1000 + i, method=method, object=OBJECTS[i], true_angle_rad=0.3,
                                    offset_mm=(0.0, 0.0), target_angle_rad=0.0, confidence=0.5, defined=True,
                                    final_angle_rad=error, error_rad=error, outcome=outcome))
    return recs


@pytest.fixture
def run_dir(tmp_path) -> Path:
    """A run directory as ``tactile-manip trials`` leaves it: run.json and trials.jsonl."""
    with TrialLog(tmp_path / "run", config={"scene": "test"}, code_version="test") as log:
        for r in paired_run():
            log.append(r)
    return tmp_path / "run"


def _assert_png(path: Path) -> None:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and len(data) > 5_000, path


# ---------------------------------------------------------------- report


def test_write_report_files(tmp_path):
    summary = write_report(tmp_path / "out", paired_run(), math.radians(5.0), title="Test run",
                           run_info={"run_id": "r1", "config_hash": "abc", "other": "dropped"})
    assert summary.methods["supermag"].successes == 5
    doc = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert doc["title"] == "Test run" and doc["run"] == {"run_id": "r1", "config_hash": "abc"}
    assert doc["tolerance_deg"] == pytest.approx(5.0)
    assert doc["methods"]["bilinear"]["successes"] == 1
    md = (tmp_path / "out" / "summary.md").read_text()
    assert md.startswith("# Test run\n")
    assert "<= 5 deg" in md
    header = ("| method | success | rate | Wilson 95 % CI | median abs err (deg) | p95 abs err (deg) | abstained "
              "| faults |")
    assert header in md
    table = md.split(header)[1].split("\n\n")[0].strip().splitlines()
    assert len(table) == 3 and all(line.count("|") == 9 for line in table)  # no stray pipe splits a cell
    assert "| supermag | 5/6 | 83.3 % | 43.6 % - 97.0 % | 2.50 |" in md
    assert "| bilinear | 1/6 | 16.7 % |" in md and "| 1 | 2 |" in md  # abstained 1, faults 2
    assert "| supermag | bilinear | 6 | 1 | 4 | 0 | 1 | 0.125 |" in md
    assert "| letter_r | 2/3 | 0/3 |" in md
    for name in ("errors.png", "success_vs_tolerance.png"):
        _assert_png(tmp_path / "out" / name)


def test_report_with_a_tag_and_a_method_that_never_executed(tmp_path):
    recs = [r for r in paired_run() if r.method == "bilinear" and r.outcome != "done"]
    write_report(tmp_path, recs, math.radians(2.5), tag=tolerance_tag(math.radians(2.5)))
    assert tolerance_tag(math.radians(5.0)) == "_5deg"
    md = (tmp_path / "summary_2.5deg.md").read_text()
    assert "| bilinear | 0/3 | 0.0 % | 0.0 % - 56.1 % | - | - | 1 | 2 |" in md
    for name in ("summary_2.5deg.json", "errors_2.5deg.png", "success_vs_tolerance_2.5deg.png"):
        assert (tmp_path / name).stat().st_size > 0


def test_the_error_histogram_zooms_on_small_errors_and_tells_methods_apart():
    from tactile_manip.trials.report import errors_figure

    fig = errors_figure(paired_run(), math.radians(5.0), title="Test run")
    near, far = fig.axes
    assert near.get_xlim() == (0.0, 10.0) and far.get_xlim()[1] >= 30.0   # a 0-10 deg zoom, the whole range
    assert far.get_yscale() == "log"                                     # a tail of single trials shows
    for ax in (near, far):
        styles = [p.get_linestyle() for p in ax.patches]
        assert len(styles) == 2 and styles[0] != styles[1]                  # one outline per method, styled apart
        assert any(line.get_xdata()[0] == pytest.approx(5.0) for line in ax.lines)  # the tolerance in both
    labels = [t.get_text() for t in near.get_legend().get_texts()]
    assert labels[0] == "supermag: 6 executed, median 2.5 deg, 0 beyond 10 deg"
    assert labels[1] == "bilinear: 3 executed, median 12 deg, 2 beyond 10 deg"
    assert labels[2] == "tolerance 5 deg"


def test_importing_the_trial_modules_pulls_in_no_matplotlib():
    code = ("import sys, tactile_manip.trials, tactile_manip.trials.log, tactile_manip.trials.stats, "
            "tactile_manip.trials.report, tactile_manip.commands.score\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('matplotlib', 'torch')))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


# ---------------------------------------------------------------- tactile-manip score


def test_score_rescores_a_saved_run(run_dir, capsys):
    assert main(["score", str(run_dir), "--tolerance-deg", "10"]) == 0
    out = capsys.readouterr().out
    assert "| supermag | 6/6 | 100.0 % |" in out and "| bilinear | 1/6 |" in out
    assert "<= 10 deg" in out
    assert json.loads((run_dir / "summary_10deg.json").read_text())["run"]["code_version"] == "test"
    _assert_png(run_dir / "success_vs_tolerance_10deg.png")
    assert main(["score", str(run_dir)]) == 0  # default 5 deg
    assert "| supermag | 5/6 |" in capsys.readouterr().out
    assert (run_dir / "summary_5deg.md").exists() and (run_dir / "summary_10deg.md").exists()


def test_score_writes_to_out(run_dir, tmp_path, capsys):
    assert main(["score", str(run_dir), "--tolerance-deg", "2.5", "--out", str(tmp_path / "elsewhere")]) == 0
    assert (tmp_path / "elsewhere" / "summary_2.5deg.md").exists()
    assert not (run_dir / "summary_2.5deg.md").exists()


def test_score_missing_dir_is_a_one_line_error(tmp_path, capsys):
    assert main(["score", str(tmp_path / "nowhere")]) == 2
    assert_one_line_error(capsys.readouterr().err, "score", "no run directory at")


def test_score_dir_without_trials(tmp_path, capsys):
    assert main(["score", str(tmp_path)]) == 2
    assert_one_line_error(capsys.readouterr().err, "score", "holds no trials.jsonl")


def test_score_empty_log(tmp_path, capsys):
    with TrialLog(tmp_path / "run", config={}, code_version="test"):
        pass
    assert main(["score", str(tmp_path / "run")]) == 2
    assert_one_line_error(capsys.readouterr().err, "score", "no trial records yet")


@pytest.mark.parametrize("tolerance", ["-1", "0", "nan", "120"])
def test_score_bad_tolerance(run_dir, capsys, tolerance):
    assert main(["score", str(run_dir), "--tolerance-deg", tolerance]) == 2
    assert_one_line_error(capsys.readouterr().err, "score", "--tolerance-deg must be in (0, 90]")


def test_score_corrupt_log_names_the_line(run_dir, capsys):
    file = run_dir / "trials.jsonl"
    lines = file.read_text().splitlines()
    file.write_text("\n".join([lines[0], "{oops", *lines[1:]]) + "\n")
    assert main(["score", str(run_dir)]) == 2
    assert_one_line_error(capsys.readouterr().err, "score", "trials.jsonl:2: not a JSON line")


def test_score_inconsistent_log_is_a_one_line_error(run_dir, capsys):
    with open(run_dir / "trials.jsonl", "a") as f:
        f.write(json.dumps(paired_run()[0].to_dict()) + "\n")  # trial 0 of supermag again
    assert main(["score", str(run_dir)]) == 2
    assert_one_line_error(capsys.readouterr().err, "score", "logged twice")
