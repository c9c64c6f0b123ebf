"""The task scripts in tasks/ refuse a run folder that holds another run in one line, like the CLI."""

import json
import subprocess
import sys
from pathlib import Path

from checks import assert_one_line_error

from tactile_manip.trials.log import FORMAT, FORMAT_VERSION, RUN_FILE

REPO = Path(__file__).resolve().parents[2]


def test_a_task_script_refuses_an_occupied_run_folder_in_one_line(tmp_path):
    run = tmp_path / "occupied"
    run.mkdir()
    (run / RUN_FILE).write_text(json.dumps({"format": FORMAT, "format_version": FORMAT_VERSION,
                                                "run_id": "earlier-run", "config_hash": "x"}))
    before = sorted(p.name for p in run.iterdir())
    proc = subprocess.run([sys.executable, str(REPO / "tasks" / "paper_experiment.py"), "--out", str(run)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2
    assert_one_line_error(proc.stderr, "paper_experiment.py", "earlier-run", "--resume", program="")
    assert sorted(p.name for p in run.iterdir()) == before  # nothing written into the other run


def test_resume_without_a_run_folder_is_a_usage_error(tmp_path):
    proc = subprocess.run([sys.executable, str(REPO / "tasks" / "paper_experiment.py"), "--resume"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2 and "--resume needs --out" in proc.stderr
