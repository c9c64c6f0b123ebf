"""The watchdog that makes a server or a link go with the command that made it, SIGKILL included."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.skipif(os.name != "posix", reason="process groups and symlinks of POSIX")

# a command that starts a long-lived process group and a link, guards both with a Lifeline, then waits to be killed
_COMMAND = r"""
import os, subprocess, sys, time
from tactile_manip.lifeline import Lifeline
server = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"], start_new_session=True)
os.symlink("/dev/null", sys.argv[1])
line = Lifeline(groups=[server.pid], links=[(sys.argv[1], "/dev/null"), (sys.argv[2], "/dev/null")], grace_s=1.0)
print(server.pid, flush=True)
if sys.argv[3] == "release":
    line.release()
    print("released", flush=True)
time.sleep(600)
"""


def _gone(pid: int, within_s: float = 10.0) -> bool:
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        try:  # a zombie of an exited child of the killed command is gone too
            with open(f"/proc/{pid}/stat") as f:
                if f.read().split(")")[-1].split()[0] == "Z":
                    return True
        except OSError:
            return True
        time.sleep(0.05)
    return False


def _run(tmp_path, mode: str):
    link, foreign = tmp_path / "link", tmp_path / "foreign"
    foreign.symlink_to("/dev/zero")  # points elsewhere: not the command's to remove
    proc = subprocess.Popen([sys.executable, "-c", _COMMAND, str(link), str(foreign), mode], stdout=subprocess.PIPE,
                            text=True)
    server = int(proc.stdout.readline())
    if mode == "release":
        assert proc.stdout.readline().strip() == "released"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    return server, link, foreign


def test_a_killed_command_takes_its_server_and_its_link_along(tmp_path):
    server, link, foreign = _run(tmp_path, "guard")
    assert _gone(server)
    deadline = time.monotonic() + 10
    while os.path.lexists(link) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not os.path.lexists(link)
    assert os.readlink(foreign) == "/dev/zero"  # a link that points elsewhere stays


def test_a_released_lifeline_touches_nothing(tmp_path):
    server, link, _ = _run(tmp_path, "release")
    try:
        time.sleep(1.0)
        assert not _gone(server, within_s=0.5) and os.path.islink(link)
    finally:
        os.killpg(server, signal.SIGKILL)
