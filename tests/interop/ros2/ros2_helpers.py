"""Helpers of the live ROS 2 tests: a free port and whether anything listens on it, ``tactile-manip serve`` run as a
user runs it, the topics a pad publishes, the types a client is given definitions of, and the independent client
(``zenoh_client.py``) started in its own process."""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

CLIENT = Path(__file__).resolve().parent / "zenoh_client.py"
TYPES = ("std_msgs/Float32MultiArray", "tactile_manip_msgs/Angle", "tactile_manip_msgs/Contact", "sensor_msgs/Image",
         "diagnostic_msgs/DiagnosticArray", "std_srvs/Trigger_Response")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


TOPICS = {"/tactile/field_raw": "std_msgs/msg/Float32MultiArray", "/tactile/field": "std_msgs/msg/Float32MultiArray",
          "/tactile/angle": "tactile_manip_msgs/msg/Angle", "/tactile/contact": "tactile_manip_msgs/msg/Contact"}
STOPS = [(signal.SIGINT, 130), (signal.SIGTERM, 143), (signal.SIGKILL, -9)]  # a signal and serve's exit status


def f32(x) -> float:
    """``x`` as the float32 a message carries."""
    return float(np.float32(x))


def stream_a_press(est, pub, seconds: float) -> tuple[list, float]:
    """Press a simulated pad with a letter, publish its every reading through ``pub`` for ``seconds``; returns the
    (reading, estimate) pairs published and the seconds it took."""
    from tactile_manip.sensors import SimulatedSensor, parse_press

    published = []
    with SimulatedSensor() as sensor:
        est.set_noise_floor(sensor.calibrate_baseline(125).noise_ut)
        sensor.play([parse_press("letter_r,t=0.2,force=10,yaw=20,rise=0.3,hold=0.5")], period_s=1.5)
        with sensor.subscribe() as frames:
            start = time.monotonic()
            while time.monotonic() - start < seconds:
                reading = frames.get(1.0).reading
                published.append((reading, pub.estimate(reading)))
            return published, time.monotonic() - start


def same(got, want) -> bool:
    """A decoded number equals the published one; NaN (``want`` NaN or None) is NaN or the client's "nan"."""
    if want is None or (isinstance(want, float) and math.isnan(want)):
        return got == "nan" or (isinstance(got, float) and math.isnan(got))
    return got == want


def check_values(vals: dict, published: list, stamps: list[int], *, frame_id: str | None = None) -> None:
    """Each topic's decoded messages (``vals[topic]``, in order) carry the published readings' and estimates'
    values and stamps, and the pad was pressed, so contact values were compared, not only NaNs."""
    contacts = 0
    for i, (reading, e) in enumerate(published):
        assert vals["/tactile/field_raw"][i]["data"] == [f32(v) for v in np.ravel(reading.field_raw_ut)]
        assert vals["/tactile/field"][i]["data"] == [f32(v) for v in np.ravel(reading.field_ut)]
        a = vals["/tactile/angle"][i]
        assert same(a["angle"], f32(e.angle.angle_rad)) and same(a["confidence"], f32(e.angle.confidence))
        assert (a["defined"], a["plausible"]) == (e.angle.defined, e.angle.plausible)
        assert frame_id is None or a["header"]["frame_id"] == frame_id
        assert a["header"]["stamp"]["sec"] * 10**9 + a["header"]["stamp"]["nanosec"] == stamps[i]
        c, s = vals["/tactile/contact"][i], e.contact
        assert (c["in_contact"], c["plausible"]) == (e.in_contact, e.plausible)
        assert same(c["force"]["z"], s.force_n) and same(c["force_sigma"]["z"], s.force_sigma_n)
        if e.in_contact:
            contacts += 1
            assert same(c["position"]["x"], s.x_mm * 1e-3) and same(c["position"]["y"], s.y_mm * 1e-3)
            assert same(c["position_sigma"]["x"], s.x_sigma_mm * 1e-3)
        else:
            assert same(c["position"]["x"], None)
    assert contacts > 20


def serve_on_taken_port(port_flag: str, *args: str) -> tuple[int, int, str, str]:
    """Run ``serve ARGS PORT_FLAG P`` with P already taken by a listener; returns (P, exit status, stdout, stderr)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        proc = serve(*args, port_flag, str(port))
        out, err = proc.communicate(timeout=60)
    return port, proc.returncode, out, err


def listening(port: int) -> bool:
    """Whether a socket listens on 127.0.0.1:``port``. The probe binds with SO_REUSEADDR, which a listener
    refuses but the TIME_WAIT of a connection the server closed does not."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return True
        return False


def wait_no_listener(port: int, timeout_s: float = 5.0) -> bool:
    """True once nothing listens on ``port`` (within ``timeout_s``)."""
    end = time.monotonic() + timeout_s
    while listening(port):
        if time.monotonic() > end:
            return False
        time.sleep(0.05)
    return True


def serve(*args: str) -> subprocess.Popen:
    """``tactile-manip serve ARGS`` in its own process, its output unbuffered."""
    return subprocess.Popen([sys.executable, "-m", "tactile_manip", "serve", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})


def wait_listening(proc: subprocess.Popen, port: int, timeout_s: float = 60.0) -> None:
    """Wait until ``proc`` listens on ``port``; fails with its stderr if it exits first."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        assert proc.poll() is None, proc.communicate()[1][-2000:]
        if listening(port):
            return
        time.sleep(0.1)
    raise AssertionError("serve did not listen")


def stop_frees_port(args: tuple[str, ...], port: int, sig: signal.Signals, status: int) -> None:
    """Run ``serve ARGS`` until it streams, stop it with ``sig``; it exits with ``status`` and leaves no listener."""
    proc = serve(*args)
    wait_listening(proc, port)
    time.sleep(1.5)  # streaming by now
    proc.send_signal(sig)
    proc.communicate(timeout=30)
    assert proc.returncode == status
    assert wait_no_listener(port), f"port {port} still taken after {sig!r}"


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
