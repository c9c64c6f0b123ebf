"""Importing the package and the simulator stays cheap: no heavy or optional package is pulled in
(docs/design.md, Layers).

Each check runs in a fresh interpreter, since this test process has long since imported everything.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("torch", "onnxruntime", "roboticstoolbox", "franky", "serial", "trimesh", "matplotlib", "cv2", "sklearn")


def _heavy_modules_after(code: str) -> list[str]:
    """Run ``code`` in a fresh interpreter; return the heavy top-level packages it left in ``sys.modules``."""
    probe = (f"{code}\nimport json, sys\n"
             f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set({list(HEAVY)!r}))))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("code", [
    "import tactile_manip",
    "import tactile_manip.sim.pair",
    "import tactile_manip.boards; tactile_manip.boards.load_board('eflesh')",
    "import tactile_manip.sim.board_press, tactile_manip.sim.magnets",
    "import tactile_manip.sim.dataset",
    "import tactile_manip.sensors",
    "import tactile_manip.collection.camera, tactile_manip.collection.camera_opencv, tactile_manip.collection.camera_sim, "
    "tactile_manip.collection.vbts_calibration, tactile_manip.collection.collect, tactile_manip.collection.collect_sim",
    "import tactile_manip.perception.reconstruct, tactile_manip.perception.pose, tactile_manip.perception.metrics",
    "import tactile_manip.perception",
    "import tactile_manip.perception.contact, tactile_manip.perception.contact_pose, "
    "tactile_manip.perception.contact_evaluation",
    # applying a fitted confidence calibration is numpy only (fitting one imports scikit-learn)
    "from tactile_manip.perception.confidence import ConfidenceCalibration; "
    "ConfidenceCalibration((0.1, 0.9), (0.2, 0.8))(0.5)",
    "import tactile_manip.robot, tactile_manip.robot.twin, tactile_manip.robot.safety, tactile_manip.robot.conformance",
    "import tactile_manip.behaviours.reorient, tactile_manip.behaviours.place",
    "import tactile_manip.trials.scene, tactile_manip.trials.runner, tactile_manip.trials.stats",
    # the CLI parser imports every command module, and `--help` must stay fast
    "import tactile_manip.cli; tactile_manip.cli.build_parser()",
])
def test_import_pulls_in_no_heavy_package(code):
    assert _heavy_modules_after(code) == []


def test_probe_sees_a_heavy_import():
    """The probe itself works: an import of matplotlib (a core dependency) is reported."""
    assert _heavy_modules_after("import tactile_manip.plots; tactile_manip.plots._pyplot()") == ["matplotlib"]
