"""`view --rerun` and `trials --rerun` leave nothing running: the server they start stops when they end (done,
failed, Ctrl-C or SIGTERM), and the Rerun options that would fail later are refused first, naming the cause."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from checks import assert_one_line_error, ctrl_c_as_in_a_terminal

pytest.importorskip("rerun", reason="the Rerun sinks need rerun-sdk (extra 'viz')")

from tactile_manip.cli import main  # noqa: E402
from tactile_manip.interop.rerun_sink import grpc_url, open_live  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
SCENE = REPO / "configs" / "scenes" / "reorient_sim.toml"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _port_is_free(port: int, host: str = "127.0.0.1") -> bool:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family) as s:
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def _rerun_processes_on(port: int) -> list[int]:
    """Pids of running `rerun` programs started for ``port`` (any user's wrapper or binary)."""
    psutil = pytest.importorskip("psutil", reason="psutil (extra 'ray') lists the processes")
    found = []
    for p in psutil.process_iter(["cmdline"]):
        cmd = p.info["cmdline"] or []
        if any("rerun" in part for part in cmd) and str(port) in cmd and "--port" in cmd:
            found.append(p.pid)
    return found


def _assert_nothing_left(port: int, host: str = "127.0.0.1") -> None:
    deadline = time.monotonic() + 5.0  # a stopped server may take a moment to release the port
    while time.monotonic() < deadline and not (_port_is_free(port, host) and not _rerun_processes_on(port)):
        time.sleep(0.1)
    free, left = _port_is_free(port, host), _rerun_processes_on(port)
    for pid in left:  # a failing run leaves no server behind either
        os.kill(pid, signal.SIGKILL)
    assert free, f"port {port} is still taken after the command ended"
    assert not left, f"rerun processes {left} of the command were still running"


def _cli(*argv: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "tactile_manip.cli", *argv], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=None if sys.platform == "win32" else ctrl_c_as_in_a_terminal)


def _wait_serving(proc: subprocess.Popen, port: int, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        if not _port_is_free(port):
            return
        time.sleep(0.1)
    pytest.fail(f"the command did not serve on port {port} within {timeout_s:.0f} s")


def test_view_serve_stops_its_server_when_done():
    port = _free_port()
    proc = _cli("view", "--sim", "--rerun", "--serve", "--rerun-port", str(port), "--seconds", "2",
                "--baseline-frames", "25")
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert "logged" in err
    _assert_nothing_left(port)


@pytest.mark.parametrize("sig, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_view_serve_stops_its_server_on_ctrl_c_and_sigterm(sig, status):
    port = _free_port()
    proc = _cli("view", "--sim", "--rerun", "--serve", "--rerun-port", str(port), "--baseline-frames", "25")
    try:
        _wait_serving(proc, port)
        time.sleep(2.0)  # the stream has begun
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == status, err
    assert "logged" in err
    _assert_nothing_left(port)


def test_view_serve_killed_outright_leaves_no_server():
    """SIGKILL runs no cleanup of the command: its watchdog (tactile_manip.lifeline) stops the server."""
    port = _free_port()
    proc = _cli("view", "--sim", "--rerun", "--serve", "--rerun-port", str(port), "--baseline-frames", "25")
    try:
        _wait_serving(proc, port)
        time.sleep(1.0)
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    _assert_nothing_left(port)
    again = _cli("view", "--sim", "--rerun", "--serve", "--rerun-port", str(port), "--baseline-frames", "25",
                 "--seconds", "1")
    _, err = again.communicate(timeout=60)
    assert again.returncode == 0, err  # the port is free for the next server
    _assert_nothing_left(port)


def test_trials_serve_stops_its_server_when_done(tmp_path):
    pytest.importorskip("roboticstoolbox", reason="simulated trials need roboticstoolbox-python (extra 'robot')")
    port = _free_port()
    proc = _cli("trials", "--config", str(SCENE), "--trials", "1", "--methods", "bilinear", "--out",
                str(tmp_path / "R"), "--quiet", "--no-frames", "--rerun", "--serve", "--rerun-port", str(port))
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == 0, err
    _assert_nothing_left(port)


def test_trials_serve_stops_its_server_on_an_error(tmp_path):
    pytest.importorskip("roboticstoolbox", reason="simulated trials need roboticstoolbox-python (extra 'robot')")
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.read_text().replace('"models/supermag.onnx"', '"no_such_model.onnx"'))
    port = _free_port()
    proc = _cli("trials", "--config", str(scene), "--methods", "supermag", "--out", str(tmp_path / "R"), "--quiet",
                "--rerun", "--serve", "--rerun-port", str(port))
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == 2 and "no_such_model" in err, err
    _assert_nothing_left(port)


def test_trials_serve_stops_its_server_on_sigterm(tmp_path):
    pytest.importorskip("roboticstoolbox", reason="simulated trials need roboticstoolbox-python (extra 'robot')")
    port = _free_port()
    proc = _cli("trials", "--config", str(SCENE), "--trials", "50", "--methods", "bilinear", "--out",
                str(tmp_path / "R"), "--quiet", "--no-frames", "--rerun", "--serve", "--rerun-port", str(port))
    try:
        _wait_serving(proc, port)
        time.sleep(1.0)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143 and "terminated" in err, err
    _assert_nothing_left(port)


def test_server_on_ipv6_loopback_receives_the_stream_and_stops():
    import rerun as rr

    if not socket.has_ipv6 or not _port_is_free(0, "::1"):
        pytest.skip("no IPv6 loopback on this machine")
    port = _free_port()
    sink = open_live(serve=True, bind="::1", port=port)
    try:
        assert sink.description == f"serving at rerun+http://[::1]:{port}/proxy"
        rr.log("x", rr.Scalars(1.0), recording=sink.recording)
    finally:
        sink.close()
    _assert_nothing_left(port, "::1")


def test_a_server_behind_the_python_wrapper_stops_too(monkeypatch):
    """`python -m rerun` runs the binary as its child: stopping the wrapper alone left the binary serving."""
    from tactile_manip.interop import rerun_sink

    monkeypatch.setattr(rerun_sink, "rerun_program", lambda: [sys.executable, "-m", "rerun"])
    port = _free_port()
    sink = open_live(serve=True, port=port)
    assert sink.process.args[:3] == [sys.executable, "-m", "rerun"]
    sink.close()
    _assert_nothing_left(port)


def test_grpc_urls_bracket_ipv6_addresses():
    assert grpc_url("::1", 9876) == "rerun+http://[::1]:9876/proxy"
    assert grpc_url("127.0.0.1", 9876) == "rerun+http://127.0.0.1:9876/proxy"
    assert grpc_url("0.0.0.0", 9876) == "rerun+http://127.0.0.1:9876/proxy"


@pytest.mark.parametrize("bind", ["127.0.0.1:80", "[::1]:9876", "localhost:80"])
def test_bind_with_a_port_is_refused_naming_rerun_port(tmp_path, capsys, bind):
    assert main(["view", "--sim", "--rerun", "--serve", "--bind", bind, "--seconds", "1"]) == 2
    assert_one_line_error(capsys.readouterr().err, "view",
                          f"--bind takes an address without a port (got '{bind}'); give the port with --rerun-port")


def test_bind_that_is_not_an_address_is_refused(capsys):
    assert main(["view", "--sim", "--rerun", "--serve", "--bind", "my-laptop", "--seconds", "1"]) == 2
    assert_one_line_error(capsys.readouterr().err, "view", "--bind: expected an IP address", "'my-laptop'")


def test_spawn_without_a_display_says_so(monkeypatch, capsys):
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    port = _free_port()
    assert main(["view", "--sim", "--rerun", "--spawn", "--rerun-port", str(port), "--seconds", "1",
                 "--baseline-frames", "25"]) == 2
    assert_one_line_error(capsys.readouterr().err, "view",
                          "no display (DISPLAY and WAYLAND_DISPLAY are unset): use --save F.rrd or --serve")
    _assert_nothing_left(port)


def test_spawn_checks_no_display_off_linux(monkeypatch):
    """macOS and Windows need no DISPLAY: the check is for the X11 and Wayland desktops."""
    from tactile_manip.interop.rerun_sink import display_problem

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    for platform in ("darwin", "win32"):
        monkeypatch.setattr(sys, "platform", platform)
        assert display_problem() is None
    monkeypatch.setattr(sys, "platform", "linux")
    assert "no display" in display_problem()
    monkeypatch.setenv("WAYLAND_DISPLAY", "wayland-0")
    assert display_problem() is None



def test_a_flush_that_does_not_finish_in_time_is_noted_and_does_not_hold_the_exit():
    from tactile_manip.interop.rerun_sink import flush_within

    class Stuck:  # a stream interrupted mid-send: rerun raises once the timeout is reached
        def flush(self, *, timeout_sec):
            raise RuntimeError(f"flush timed out after {timeout_sec} s")

    class Old:  # rerun-sdk 0.24: no timeout, a blocking flush
        flushed = 0

        def flush(self):
            self.flushed += 1

    notes: list[str] = []
    flush_within(Stuck(), 0.5, notes)
    assert notes == ["rerun: the last data was not flushed within 0.5 s (RuntimeError: flush timed out after 0.5 s)"]
    old = Old()
    flush_within(old, 0.5, notes)
    assert old.flushed == 1 and len(notes) == 1
