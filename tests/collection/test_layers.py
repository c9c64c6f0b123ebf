"""DESIGN.md 2: the collection modules live in sensors/ and import no perception, robot or learning code."""

from __future__ import annotations

import json
import subprocess
import sys

MODULES = ("camera", "camera_opencv", "camera_sim", "vbts", "vbts_calibration", "sync", "force", "pair_log", "collect",
           "collect_sim")


def test_collection_modules_import_no_upper_layer():
    code = ("import json, sys\n" + "".join(f"import tactile_manip.sensors.{m}\n" for m in MODULES)
            + "import tactile_manip.commands.collect\n"
            + "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[:2] in "
              "(['tactile_manip', 'perception'], ['tactile_manip', 'robot'], ['tactile_manip', 'learning']))))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
