"""`pip install -e ".[dev]"` brings what the suite needs (torch as the README installs it), and a run without
torch says so in words instead of skipping a hundred tests quietly."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from checks import TORCH_MISSING

ROOT = Path(__file__).resolve().parents[1]
README_TORCH = "2.13.0"  # the README's `pip install torch==2.13.0` (the CPU build) comes first

# a sitecustomize that hides torch from this interpreter, as on a machine without it
NO_TORCH = '''import sys
class _NoTorch:
    def find_spec(self, name, path=None, target=None):
        if name == "torch" or name.startswith("torch."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, _NoTorch())
'''


def test_the_dev_extra_asks_for_torch_that_the_readmes_cpu_build_satisfies():
    import tomllib

    requirements = pytest.importorskip("packaging.requirements", reason="reading requirements needs packaging")
    dev = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["dev"]
    torch = [r for r in map(requirements.Requirement, dev) if r.name == "torch"]
    assert len(torch) == 1, dev
    assert torch[0].specifier.contains(README_TORCH)       # after the README's torch, pip installs no other
    assert torch[0].specifier.contains(f"{README_TORCH}+cpu")  # the CPU wheel's local version also satisfies it


def test_without_torch_the_run_says_so_loudly(tmp_path):
    (tmp_path / "sitecustomize.py").write_text(NO_TORCH)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    done = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "tests/learning/test_model.py",
                           "tests/bench/test_report_parts.py"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    out = done.stdout
    assert f"WARNING: {TORCH_MISSING}" in out                       # in the header, before any test runs
    assert f"2 tests or test files SKIPPED: {TORCH_MISSING}" in out  # test_model.py and the tiny-model test
    assert "passed" in out                                          # the rest of the files still ran
