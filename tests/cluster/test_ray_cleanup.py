"""``simulate --ray local`` leaves no process behind, however it ends: SIGKILL (which no process can trap),
SIGTERM and Ctrl-C (extra ``ray``)."""

import importlib.util
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from checks import ctrl_c_as_in_a_terminal

if importlib.util.find_spec("ray") is None:
    pytest.skip("the 'ray' extra is not installed", allow_module_level=True)
psutil = pytest.importorskip("psutil", reason="the 'ray' extra (psutil) is not installed")

pytestmark = [pytest.mark.ray, pytest.mark.slow]
REPO = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 120.0  # a cold Ray instance on a loaded 2-core machine
GONE_TIMEOUT_S = 20.0


def _session_processes(cli: psutil.Process, seen: dict) -> None:
    """Adds every process below ``cli`` (Ray's, and the watchdog) to ``seen`` (pid -> Process, so that a reused
    pid is not counted), and the children of those already seen: the agents are the raylet's, and stay when it
    dies."""
    try:
        below = cli.children(recursive=True)
    except psutil.Error:
        below = []
    for p in below:
        seen.setdefault(p.pid, p)
    for p in list(seen.values()):
        try:
            for c in p.children(recursive=True):
                seen.setdefault(c.pid, c)
        except psutil.Error:
            pass


def _name(p: psutil.Process) -> str:
    try:
        return p.name()
    except psutil.Error:
        return ""


def _alive(procs) -> list:
    out = []
    for p in procs:
        try:
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                out.append(p)
        except psutil.Error:
            pass
    return out


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGINT], ids=["kill", "term", "int"])
def test_no_process_of_the_session_outlives_the_command(tmp_path, sig):
    cmd = [sys.executable, "-m", "tactile_manip.cli", "simulate", "--scale", "0.05", "--ray", "--workers", "1",
           "--out", str(tmp_path / "d.npz")]
    log = tmp_path / "stderr.txt"
    with log.open("wb") as stderr:  # a file, not a pipe: a full pipe would stall the command
        proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=stderr,
                                start_new_session=True,  # a process group of its own, as a shell gives a job
                                preexec_fn=ctrl_c_as_in_a_terminal)
    cli = psutil.Process(proc.pid)
    seen: dict = {}
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline and proc.poll() is None:
            _session_processes(cli, seen)
            names = {_name(p) for p in _alive(seen.values())}
            if {"ray::DashboardAgent", "ray::RuntimeEnvAgent"} <= names and any("simulate_block" in n for n in names):
                break
            time.sleep(0.2)
        else:
            pytest.fail(f"Ray did not start its agents and a task within {START_TIMEOUT_S:.0f} s "
                        f"(exit status {proc.poll()}): {log.read_text()[-2000:]}")
        _session_processes(cli, seen)
        os.kill(proc.pid, sig)
        proc.wait(timeout=60)
        deadline = time.monotonic() + GONE_TIMEOUT_S
        while time.monotonic() < deadline and _alive(seen.values()):
            time.sleep(0.2)
        left = [(p.pid, _name(p)) for p in _alive(seen.values())]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for p in _alive(seen.values()):  # leave nothing behind when the test fails either
            try:
                p.kill()
            except psutil.Error:
                pass
    assert not left, f"processes of the session still run {GONE_TIMEOUT_S:.0f} s after {sig.name}: {left}"
    if sig != signal.SIGKILL:
        err = log.read_text()
        assert "Traceback" not in err, err
        stop = "terminated" if sig == signal.SIGTERM else "interrupted"
        assert proc.returncode == (143 if sig == signal.SIGTERM else 130), err
        assert err.rstrip().endswith(f"tactile-manip simulate: {stop}"), err
