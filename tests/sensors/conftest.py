"""Shared fixtures: the firmware emulator as a separate process, driven through a real pty."""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

START_TIMEOUT_S = 60.0  # interpreter start, imports and press precompute on a loaded 2-core machine


class EmulatorProcess:
    """``tactile-manip emulate ARGS`` in a child process; ``path`` is the first line it prints."""

    def __init__(self, args: list[str], log: Path) -> None:
        self.log = log
        self._log_file = open(log, "w")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen([sys.executable, "-m", "tactile_manip", "emulate", *args],
                                     stdout=subprocess.PIPE, stderr=self._log_file, text=True)
        self._lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()
        self.path = self._line(START_TIMEOUT_S)

    def _pump(self) -> None:
        for line in self.proc.stdout:
            self._lines.put(line.strip())

    def _line(self, timeout_s: float) -> str:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            try:
                return self._lines.get(timeout=0.1)
            except queue.Empty:
                if self.proc.poll() is not None and self._lines.empty():
                    break
        self.stop()
        raise AssertionError(f"emulator printed no line (exit status {self.proc.poll()}); log:\n"
                             f"{self.log.read_text()}")

    def report(self, timeout_s: float = 60.0) -> dict:
        """The JSON report printed when the stream ends (frame or time budget spent)."""
        return json.loads(self._line(timeout_s))

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log_file.close()


@pytest.fixture
def emulator(tmp_path):
    """Start emulators: ``emulator("--duration-s", "5", ...)``; all are stopped at the end of the test."""
    started: list[EmulatorProcess] = []

    def start(*args: str) -> EmulatorProcess:
        e = EmulatorProcess(list(args), tmp_path / f"emulator{len(started)}.log")
        started.append(e)
        return e

    yield start
    for e in started:
        e.stop()


def _wait_until(predicate, timeout_s: float, poll_s: float = 0.02) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(poll_s)
    return bool(predicate())


@pytest.fixture
def wait_until():
    """``wait_until(predicate, timeout_s)``: poll until true or timed out; returns the last value."""
    return _wait_until


@pytest.fixture(scope="session")
def streaming_emulator(tmp_path_factory):
    """One fault-free emulator streaming for the whole session (tests open and close its port in turn)."""
    e = EmulatorProcess(["--duration-s", "900", "--linger-s", "0", "--seed", "5"],
                        tmp_path_factory.mktemp("emulator") / "shared.log")
    yield e
    e.stop()


@pytest.fixture(scope="session")
def anyskin_emulator(tmp_path_factory):
    """One emulator streaming the ReSkin/AnySkin binary sketch's bytes for the whole session."""
    e = EmulatorProcess(["--duration-s", "900", "--linger-s", "0", "--seed", "6", "--wire-format", "anyskin"],
                        tmp_path_factory.mktemp("emulator") / "anyskin.log")
    yield e
    e.stop()


@pytest.fixture(scope="session")
def sim_recording(tmp_path_factory) -> Path:
    """About 1.2 s of the simulated sensor at 125 Hz, recorded with the Recorder."""
    from tactile_manip.sensors import Recorder, SimulatedSensor, SimulatedSensorConfig

    path = tmp_path_factory.mktemp("recording") / "sim.tmrec"
    with SimulatedSensor(SimulatedSensorConfig(seed=11)) as sensor:
        Recorder(sensor, path).run(duration_s=1.2)
    return path
