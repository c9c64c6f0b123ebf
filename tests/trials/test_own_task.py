"""A task of one's own (docs/your_task.md): one module outside the package, named by a scene as "module:Class" or
by one line of the registry's table, runs through `tactile-manip trials` and `score` like a shipped task."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest
from checks import assert_one_line_error

from tactile_manip.behaviours import registry
from tactile_manip.cli import main

pytest.importorskip("roboticstoolbox")
pytest.importorskip("onnxruntime")

REPO = Path(__file__).resolve().parents[2]
PAGE = REPO / "docs" / "your_task.md"
EXAMPLE = REPO / "examples" / "your_task"


def _fenced(lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```", PAGE.read_text(), flags=re.S | re.M)


def test_the_page_shows_the_example_files_as_they_are() -> None:
    assert _fenced("python")[0] == (EXAMPLE / "lift.py").read_text()
    assert _fenced("toml")[0] == (EXAMPLE / "lift_sim.toml").read_text()


@pytest.fixture
def workspace(tmp_path, monkeypatch):
    """A folder outside the package holding the user's task module (a copy of the example under another name)
    and a scene naming it; the working directory while the test runs."""
    (tmp_path / "my_lab").mkdir()
    (tmp_path / "my_lab" / "lift_task.py").write_text((EXAMPLE / "lift.py").read_text())
    scene = (EXAMPLE / "lift_sim.toml").read_text().replace('"examples.your_task.lift:Lift"',
                                                            '"my_lab.lift_task:Lift"')
    scene = scene.replace('"models/supermag.onnx"', f'"{REPO / "models" / "supermag.onnx"}"')
    (tmp_path / "lift.toml").write_text(scene.replace("trials = 6", "trials = 2"))
    monkeypatch.chdir(tmp_path)
    for name in [m for m in sys.modules if m.split(".")[0] == "my_lab"]:  # another test's my_lab
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setattr(sys, "path", list(sys.path))
    yield tmp_path
    for name in [m for m in sys.modules if m.split(".")[0] == "my_lab"]:
        del sys.modules[name]


def test_a_task_module_outside_the_package_runs_through_trials_and_score(workspace) -> None:
    assert main(["trials", "--config", "lift.toml", "--out", "run", "--quiet"]) == 0
    lines = [json.loads(line) for line in (workspace / "run" / "trials.jsonl").read_text().splitlines()]
    assert [(r["trial"], r["method"], r["task"]) for r in lines] == [
        (0, "supermag", "lift"), (0, "blind", "lift"), (1, "supermag", "lift"), (1, "blind", "lift")]
    assert all(r["outcome"] == "done" and r["extra"]["lift_mm"] == 20.0 for r in lines)
    ours = [r for r in lines if r["method"] == "supermag"]
    assert all(abs(r["error_rad"]) < 0.05 for r in ours)  # the angle read after the lift is the presented one
    doc = json.loads((workspace / "run" / "summary.json").read_text())
    assert doc["task"] == "lift" and doc["title"] == "Lift trials: lift_sim"
    assert set(doc["lift_change"]) == {"supermag", "blind"}
    text = (workspace / "run" / "summary.md").read_text()
    assert "## How far the angle read moved over the lift" in text
    assert "Success: outcome `done` and |angle read after the lift - true angle| <= 5 deg" in text
    assert main(["score", "run", "--tolerance-deg", "2"]) == 0
    assert "## How far the angle read moved over the lift" in (workspace / "run" / "summary_2deg.md").read_text()


def test_one_line_of_the_table_names_a_task_as_the_shipped_ones_are_named(workspace, monkeypatch) -> None:
    monkeypatch.setitem(registry.TASKS, "lift", "my_lab.lift_task:Lift")
    scene = (workspace / "lift.toml").read_text().replace('"my_lab.lift_task:Lift"', '"lift"')
    (workspace / "named.toml").write_text(scene.replace("trials = 2", "trials = 1"))
    assert main(["trials", "--config", "named.toml", "--out", "run", "--quiet", "--methods", "supermag"]) == 0
    assert json.loads((workspace / "run" / "summary.json").read_text())["task"] == "lift"


@pytest.mark.parametrize("change, message", [
    (('"my_lab.lift_task:Lift"', '"my_lab.nowhere:Lift"'), "cannot import my_lab.nowhere"),
    (('"my_lab.lift_task:Lift"', '"my_lab.lift_task:LiftConfig"'), "has no Task subclass called LiftConfig"),
    (('"my_lab.lift_task:Lift"', '"lift"'), "task must be one of reorient, place, grip or 'module:Class'"),
    (("height_mm = 20.0", "height_m = 0.02"), "unknown key(s) lift.height_m"),
    (("height_mm = 20.0", "height_mm = -1.0"), "lift.height_mm"),
])
def test_a_bad_task_or_setting_is_one_line_naming_the_file(workspace, capsys, change, message) -> None:
    (workspace / "bad.toml").write_text((workspace / "lift.toml").read_text().replace(*change))
    assert main(["trials", "--config", "bad.toml", "--out", "run", "--quiet"]) == 2
    assert_one_line_error(capsys.readouterr().err, "trials", message)
    assert not (workspace / "run").exists()


def test_a_task_whose_log_fields_break_records_an_error_and_the_run_goes_on(workspace) -> None:
    (workspace / "my_lab" / "broken.py").write_text(
        "from my_lab.lift_task import Lift\n\n\nclass Broken(Lift):\n"
        "    def record(self, result):\n        raise KeyError('no such field')\n")
    scene = (workspace / "lift.toml").read_text().replace('"my_lab.lift_task:Lift"', '"my_lab.broken:Broken"')
    (workspace / "broken.toml").write_text(scene)
    assert main(["trials", "--config", "broken.toml", "--out", "run", "--quiet"]) == 0
    lines = [json.loads(line) for line in (workspace / "run" / "trials.jsonl").read_text().splitlines()]
    assert len(lines) == 4 and all(r["outcome"] == "error" and r["task"] == "lift" for r in lines)
    assert all("KeyError while logging the trial" in r["detail"] for r in lines)


SQUEEZE = '''from tactile_manip.behaviours.skills import Abort, grasp, read_pad
from tactile_manip.behaviours.task import Task, TaskResult


class Squeeze(Task):
    def run(self, trial):
        result = TaskResult("error")
        try:
            grasp(trial.arm, trial.gripper, trial.object_width_m, self.behaviour)
            result.estimate = read_pad(trial.sensor, trial.estimator, self.behaviour).angle
            result.outcome = "done"
        except Abort as stop:
            result.outcome, result.detail = stop.outcome, stop.detail
        return result
'''
RECORD = '''
    def record(self, result):
        return {"error_rad": 0.0 if result.outcome == "done" else None}
'''


def _squeeze_scene(workspace, source: str) -> None:
    (workspace / "my_lab" / "squeeze.py").write_text(source)
    scene = (workspace / "lift.toml").read_text().replace('"my_lab.lift_task:Lift"', '"my_lab.squeeze:Squeeze"')
    (workspace / "squeeze.toml").write_text(scene.replace("[lift]", "").replace("height_mm = 20.0", ""))


def test_a_task_is_run_and_record_alone_named_after_its_class(workspace) -> None:
    _squeeze_scene(workspace, SQUEEZE + RECORD)
    assert main(["trials", "--config", "squeeze.toml", "--out", "run", "--quiet", "--methods", "supermag"]) == 0
    lines = [json.loads(line) for line in (workspace / "run" / "trials.jsonl").read_text().splitlines()]
    assert [(r["task"], r["outcome"]) for r in lines] == [("squeeze", "done")] * 2
    assert json.loads((workspace / "run" / "summary.json").read_text())["title"] == "Squeeze trials: lift_sim"


def test_a_task_without_its_log_fields_is_one_line_before_the_run_folder(workspace, capsys) -> None:
    _squeeze_scene(workspace, SQUEEZE)
    assert main(["trials", "--config", "squeeze.toml", "--out", "run", "--quiet"]) == 2
    assert_one_line_error(capsys.readouterr().err, "trials", "task 'my_lab.squeeze:Squeeze'", "record")
    assert not (workspace / "run").exists()
