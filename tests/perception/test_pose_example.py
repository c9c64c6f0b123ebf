"""examples/tactile_pose.py runs from any folder and flags its undefined estimates as such."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_the_pose_example_runs_and_flags_the_empty_pad_as_undefined(tmp_path):
    pytest.importorskip("onnxruntime", reason="the example runs the shipped model (the onnx extra)")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, str(ROOT / "examples" / "tactile_pose.py")], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    lines = done.stdout.splitlines()
    assert len(lines) == 7, done.stdout  # five streamed estimates, the 8-frame estimate, the empty pad
    assert lines[-1] == "empty pad: angle UNDEFINED (no contact field): no angle to act on"
    for line in lines:  # an angle is printed only for a defined estimate, and never with zero confidence
        assert ("UNDEFINED" in line) != ("deg  confidence" in line), line
        assert "confidence 0.00" not in line, line
    steady = re.match(r"8-frame estimate: angle ([-+]\d+\.\d+) deg", lines[5])
    assert steady and abs(float(steady.group(1)) - 30.0) < 3.0, lines[5]
