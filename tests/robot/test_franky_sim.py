"""The franky backend against franky-sim: a MuJoCo FR3 + Franka Hand that speaks the libfranka protocol.

franky-sim runs as a child process in its own process group, bound to a free 127.x.y.z loopback address (its
ports are libfranka's fixed 1337 / 1338, so it picks the address: the first one whose ports are free) and it
prints that address when it is ready (about 4 s here; MuJoCo needs no display or OpenGL without --render).
The server is always killed with its whole process group. Skipped when franky or franky-sim is missing, and
skipped with the server's stderr when the simulator cannot start on this machine.

The same :func:`run_conformance` the twin passes runs here, with the gripper: franky-sim simulates the Franka
Hand. Realtime is not enforced (no PREEMPT_RT kernel in CI); the dynamics factor is the backend's low default.
"""

from __future__ import annotations

import importlib.util

import os
import re
import signal
import subprocess
import sys
import threading
from collections import deque

import numpy as np
import pytest

pytest.importorskip("franky", reason='franky-control is not installed: pip install -e ".[franky]"')
# the simulator runs in its own process: only check it is installed (importing it here would load MuJoCo,
# whose bindings print reference-leak noise when this test process exits)
if importlib.util.find_spec("franky_sim") is None:
    pytest.skip("franky-sim is not installed: pip install franky-sim", allow_module_level=True)

from tactile_manip.errors import SafetyLimitError  # noqa: E402
from tactile_manip.robot.conformance import run_conformance  # noqa: E402
from tactile_manip.robot.franky_arm import FrankyArm, FrankyConfig, FrankyGripper  # noqa: E402

pytestmark = pytest.mark.slow

READY_TIMEOUT_S = 90.0  # interpreter, MuJoCo and pinocchio start on a loaded 2-core machine (~4 s idle)
_READY = re.compile(r"Connect to the server using '(127\.\d+\.\d+\.\d+)'")
# `franky-sim --simulator auto` tries the back-ends in directory order and gives up at the first that does
# not import (genesis is not installed), so the MuJoCo back-end is named explicitly.
_SERVER = [sys.executable, "-c", "import sys; from franky_sim import run_server_main; sys.exit(run_server_main())",
           "--simulator", "mujoco"]


class FrankySimServer:
    """franky-sim in its own process group; ``host`` is the loopback address it serves on."""

    def __init__(self, stderr_path: str) -> None:
        self._stderr_path = stderr_path
        self._stderr = open(stderr_path, "wb")  # noqa: SIM115 - closed in stop()
        self._stdout: deque[str] = deque(maxlen=50)
        self._ready = threading.Event()
        self.host: str | None = None
        self.proc = subprocess.Popen(_SERVER, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=self._stderr,
                                     text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"), start_new_session=True)
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        # keeps draining stdout after the ready line, so the server never blocks on a full pipe
        for line in self.proc.stdout:
            self._stdout.append(line.rstrip())
            match = _READY.search(line)
            if match and self.host is None:
                self.host = match.group(1)
                self._ready.set()
        self._ready.set()  # exited: stop waiting

    def wait_ready(self, timeout_s: float) -> str | None:
        """The address once the server accepts connections; None when it exited or timed out (see why_not)."""
        self._ready.wait(timeout_s)
        return self.host

    def why_not(self) -> str:
        self._stderr.flush()
        with open(self._stderr_path, "rb") as f:
            err = f.read().decode(errors="replace").strip().splitlines()
        state = f"exited with code {self.proc.poll()}" if self.proc.poll() is not None else "still not ready"
        tail = " | ".join((err or list(self._stdout))[-8:])
        return f"franky-sim could not start on this machine ({state}): {tail or 'no output'}"

    def stop(self) -> None:
        for sig, wait_s in ((signal.SIGTERM, 10.0), (signal.SIGKILL, 10.0)):
            if self.proc.poll() is not None:
                break
            try:
                os.killpg(self.proc.pid, sig)  # the group is ours: start_new_session made the server its leader
            except ProcessLookupError:
                break
            try:
                self.proc.wait(wait_s)
            except subprocess.TimeoutExpired:
                continue
        self._stderr.close()


@pytest.fixture(scope="module")
def franky_sim_host(tmp_path_factory):
    server = FrankySimServer(str(tmp_path_factory.mktemp("franky_sim") / "stderr.log"))
    try:
        host = server.wait_ready(READY_TIMEOUT_S)
        if host is None:
            pytest.skip(server.why_not())
        yield host
    finally:
        server.stop()


def _config(host: str) -> FrankyConfig:
    return FrankyConfig(host=host, enforce_realtime=False)  # default relative_dynamics_factor 0.05


def test_franky_backend_passes_conformance_on_franky_sim(franky_sim_host):
    config = _config(franky_sim_host)
    report = run_conformance(FrankyArm(config), FrankyGripper(config))
    print(report.summary())
    report.raise_if_failed()
    assert report.result("gripper").detail.startswith("open:")  # the hand was really checked, not skipped


def test_joint_target_outside_the_fr3_limits_is_refused_before_franky(franky_sim_host):
    with FrankyArm(_config(franky_sim_host)) as arm:
        before = arm.state().q_rad
        target = arm.home_q_rad
        target[3] = arm.q_max_rad[3] + 0.05  # joint 4 must stay below -0.1518 rad on an FR3
        with pytest.raises(SafetyLimitError, match="joint 4"):
            arm.move_joints(target)
        np.testing.assert_allclose(arm.state().q_rad, before, atol=1e-3)


def test_grasp_on_franky_sims_hand(franky_sim_host):
    # franky-sim's hand drives the fingers to the requested width (closed fingers stop ~1.6 mm apart) rather than
    # closing until they meet resistance, and it answers a grasp outside the tolerance with "failed" where a real
    # hand answers "unsuccessful": libfranka raises for the first and returns False for the second. So only a
    # successful grasp is checked here; the missed grasp (a value, not an exception) is in test_franky_unit.py.
    with FrankyGripper(_config(franky_sim_host)) as gripper:
        gripper.open()
        held = gripper.grasp(0.0, 20.0, speed_m_s=0.05, epsilon_inner_m=0.005, epsilon_outer_m=0.005)
        assert held.success and held.force_n == 20.0 and 0.0 <= held.width_m <= 0.005 and held.duration_s > 0.0
        assert gripper.state().is_grasped
        gripper.open()
        assert not gripper.state().is_grasped
