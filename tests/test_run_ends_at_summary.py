"""A test run ends with pytest's summary line: nothing prints after it.

The known offender is nanobind's leak report at interpreter exit ("nanobind: leaked 38 instances!" and some 70
lines more): roboticstoolbox keeps its robots in class-level caches, and with torch loaded in the same process
they outlive the extensions' cleanup. The run here is the smallest that showed it: one twin test, torch loaded.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RUN_WITH_TORCH = "import sys, torch, pytest; sys.exit(pytest.main(sys.argv[1:]))"


def test_nothing_prints_after_the_summary_line():
    pytest.importorskip("roboticstoolbox", reason="the kinematic twin needs roboticstoolbox-python")
    pytest.importorskip("torch", reason="the report shows only with torch loaded")
    done = subprocess.run([sys.executable, "-c", RUN_WITH_TORCH, "-q", "-p", "no:cacheprovider",
                           "tests/robot/test_twin.py::test_fk_ik_round_trip"],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert re.fullmatch(r"=*\s*1 passed.* in [\d.]+s.*", done.stdout.rstrip("\n").splitlines()[-1]), done.stdout
    assert done.stderr == ""
