"""A task is an object: the layers that run, log, score, export and benchmark trials never name a shipped task,
apart from the one table that names them all (tactile_manip/behaviours/registry.py)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import tactile_manip
from tactile_manip.behaviours.registry import DEFAULT_TASK, TASKS, task_class
from tactile_manip.behaviours.task import Task

PACKAGE = Path(tactile_manip.__file__).parent
NAMELESS = ("trials", "cluster", "commands", "interop", "bench")  # the folders that must not name a task
QUOTED = re.compile(r"[\"'`](" + "|".join(TASKS) + r")[\"'`]")


def _namings(path: Path) -> list[str]:
    """Where ``path`` names a shipped task: the name quoted anywhere in its text (code, docstrings, comments),
    a string constant that is the name, or an f-string that starts with it (``f"reorient {obj}"``)."""
    text = path.read_text()
    found = [f"{path.name}:{text.count(chr(10), 0, m.start()) + 1}: {m.group(0)}" for m in QUOTED.finditer(text)]
    tree = ast.parse(text)
    pieces = {id(v) for node in ast.walk(tree) if isinstance(node, ast.JoinedStr) for v in node.values}
    for node in ast.walk(tree):
        if (isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in pieces
                and node.value.strip() in TASKS):
            found.append(f"{path.name}:{node.lineno}: {node.value!r}")
        elif isinstance(node, ast.JoinedStr) and node.values and isinstance(node.values[0], ast.Constant):
            lead = str(node.values[0].value).split(" ")[0]
            if lead in TASKS:
                found.append(f"{path.name}:{node.lineno}: f-string {node.values[0].value!r}")
    return found


def test_no_module_that_runs_logs_or_reports_trials_names_a_shipped_task() -> None:
    offenders = {f"{folder}/{p.relative_to(PACKAGE / folder)}": hits for folder in NAMELESS
                 for p in sorted((PACKAGE / folder).rglob("*.py")) if (hits := _namings(p))}
    assert offenders == {}


def test_the_scan_sees_each_way_of_naming_a_task(tmp_path) -> None:
    """The scan itself works: a quoted name, a bare constant and an f-string lead are each caught; the words in
    prose are not (a grip force, a scene called reorient_sim)."""
    sample = tmp_path / "sample.py"
    sample.write_text('"""Runs the reorient_sim scene and logs the grip force."""\n'
                      'A = "grip"\n'
                      "B = {'place': 1}\n"
                      'C = f"reorient {A} to 0 deg"\n'
                      'D = " place "\n')
    hits = _namings(sample)
    assert sorted(int(h.split(":")[1]) for h in hits) == [2, 2, 3, 3, 4, 5]


def test_the_table_names_every_shipped_task_and_each_is_a_task() -> None:
    assert DEFAULT_TASK in TASKS
    for name in TASKS:
        cls = task_class(name)
        assert issubclass(cls, Task) and cls.name == name and cls.title
