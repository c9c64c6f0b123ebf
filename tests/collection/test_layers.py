"""docs/design.md, Layers: collection/ builds on sensors/ and data/ and imports no perception, robot or learning code;
sensors/ holds sensors only and never imports collection/."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import tactile_manip

PACKAGE = Path(tactile_manip.__file__).parent
MODULES = ("camera", "camera_opencv", "camera_sim", "vbts", "vbts_calibration", "sync", "force", "pair_log", "collect",
           "collect_sim")


def test_collection_modules_import_no_upper_layer():
    code = ("import json, sys\n" + "".join(f"import tactile_manip.collection.{m}\n" for m in MODULES)
            + "import tactile_manip.commands.collect\n"
            + "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[:2] in "
              "(['tactile_manip', 'perception'], ['tactile_manip', 'robot'], ['tactile_manip', 'learning']))))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []


def _imported(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_sensors_hold_sensors_only():
    forbidden = ("tactile_manip.collection", "tactile_manip.perception", "tactile_manip.robot",
                 "tactile_manip.learning")
    offenders = {str(p.relative_to(PACKAGE)): sorted(n for n in _imported(p) if n.startswith(forbidden))
                 for p in (PACKAGE / "sensors").rglob("*.py")}
    assert {k: v for k, v in offenders.items() if v} == {}
    assert not any((PACKAGE / "sensors" / f"{m}.py").exists() for m in MODULES)  # they live in collection/
