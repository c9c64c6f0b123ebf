"""Helpers of the live ROS 2 tests: a free port, the types a client is given definitions of, and the independent
client (``zenoh_client.py``) started in its own process."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

CLIENT = Path(__file__).resolve().parent / "zenoh_client.py"
TYPES = ("std_msgs/Float32MultiArray", "tactile_manip_msgs/Angle", "tactile_manip_msgs/Contact", "sensor_msgs/Image",
         "diagnostic_msgs/DiagnosticArray", "std_srvs/Trigger_Response")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listening(port: int) -> bool:
    """Whether anything accepts TCP connections on 127.0.0.1:``port``."""
    with socket.socket() as s:
        s.settimeout(1.0)
        try:
            s.connect(("127.0.0.1", port))
        except OSError:
            return False
        return True


def wait_no_listener(port: int, timeout_s: float = 5.0) -> bool:
    """True once nothing listens on ``port`` (within ``timeout_s``)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if not listening(port):
            return True
        time.sleep(0.05)
    return not listening(port)


class Client:
    """The independent subscriber, running in its own process until its seconds are up."""

    def __init__(self, port: int, defs: Path, out: Path, *, seconds: float, extra: tuple[str, ...] = ()) -> None:
        self.out = out
        self.proc = subprocess.Popen([sys.executable, str(CLIENT), "--connect", f"tcp/127.0.0.1:{port}",
                                      "--defs", str(defs), "--seconds", str(seconds), "--out", str(out), *extra],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        if line.strip() != "ready":
            self.proc.kill()
            raise AssertionError(f"client did not start: {line!r} {self.proc.stderr.read()[-2000:]}")

    def result(self, timeout_s: float = 60.0) -> dict:
        _, err = self.proc.communicate(timeout=timeout_s)
        assert self.proc.returncode == 0, err[-3000:]
        return json.loads(self.out.read_text())

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait()
