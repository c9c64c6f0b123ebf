"""Where a live Rerun recording goes: a ``.rrd`` file, a viewer we start, or a gRPC server on this machine.

The viewer and the server are the ``rerun`` program of the installed rerun-sdk, started with ``--bind`` so they
listen on 127.0.0.1 unless the caller asks for another address: the SDK's own ``rr.spawn`` and
``rr.serve_grpc`` listen on every interface. The logging process then connects to it over gRPC. The program
runs as a process group of its own: a server is stopped with everything in that group when the sink closes,
and a viewer is not hit by the terminal's Ctrl-C.
"""

from __future__ import annotations

import errno
import importlib.util
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from tactile_manip.interop.rerun_log import APPLICATION_ID, require_rerun
from tactile_manip.lifeline import Lifeline

DEFAULT_PORT = 9876          # Rerun's own default gRPC port
LOCALHOST = "127.0.0.1"
START_TIMEOUT_S = 20.0       # a cold viewer or server takes a few seconds to listen
STOP_TIMEOUT_S = 5.0         # a server asked to stop is killed after this long
FLUSH_TIMEOUT_S = 10.0       # the last data of a live stream waits this long at most on exit
NO_DISPLAY = "no display (DISPLAY and WAYLAND_DISPLAY are unset): use --save F.rrd or --serve"
_WINDOWS = sys.platform == "win32"


def rerun_program() -> list[str]:
    """The command that runs the ``rerun`` program of the installed rerun-sdk.

    The binary that the ``rerun_cli`` package ships, where it is found (``$RERUN_CLI_PATH`` overrides it, as it
    does for ``python -m rerun``); else ``python -m rerun``, a wrapper that runs the binary as its child.
    """
    if os.environ.get("RERUN_CLI_PATH"):
        return [os.environ["RERUN_CLI_PATH"]]
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin:
        folder = Path(spec.origin).parent
        names = ("rerun.exe",) if _WINDOWS else (os.path.join("Rerun.app", "Contents", "MacOS", "Rerun"), "rerun")
        for name in names:
            if (folder / name).is_file():
                return [str(folder / name)]
    return [sys.executable, "-m", "rerun"]


def viewer_command(*, serve: bool, bind: str, port: int) -> list[str]:
    """The ``rerun`` command line of a viewer (``serve=False``) or a viewer-less gRPC server, on ``bind:port``."""
    cmd = [*rerun_program(), "--bind", bind, "--port", str(port)]
    return cmd + ["--serve-grpc"] if serve else cmd


def grpc_host(bind: str) -> str:
    """The address to reach a server bound to ``bind`` from this machine."""
    return LOCALHOST if bind in ("0.0.0.0", "::", "") else bind


def grpc_url(host: str, port: int) -> str:
    """The proxy URL an SDK or a viewer connects to (an IPv6 address in brackets)."""
    host = grpc_host(host)
    return f"rerun+http://{f'[{host}]' if ':' in host else host}:{port}/proxy"


def display_problem() -> str | None:
    """Why a viewer window cannot open here (X11 and Wayland desktops: no display set), or None."""
    if sys.platform in ("darwin", "win32", "cygwin"):
        return None
    if any(os.environ.get(name) for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")):
        return None
    return NO_DISPLAY


@dataclass
class LiveSink:
    """An open recording and the process behind it (None for a file); :meth:`close` flushes and stops it.

    A spawned viewer is left running (it is the user's window); a server this process started is stopped,
    with any process it started.
    """

    recording: object
    description: str
    process: subprocess.Popen | None = None
    stop_process: bool = False
    notes: list[str] = field(default_factory=list)
    lifeline: Lifeline | None = None  # stops the server should this process die without closing the sink

    def close(self) -> None:
        try:
            flush_within(self.recording, FLUSH_TIMEOUT_S, self.notes)
            self.recording.disconnect()
        finally:
            if self.process is not None and self.stop_process:
                stop_process_group(self.process)
            if self.lifeline is not None:
                self.lifeline.release()

    def __enter__(self) -> LiveSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_live(*, save: str | Path | None = None, spawn: bool = False, serve: bool = False, bind: str = LOCALHOST,
              port: int = DEFAULT_PORT, recording_name: str = "", default_blueprint=None) -> LiveSink:
    """A recording stream with exactly one sink: ``save`` (a file), ``spawn`` (a viewer) or ``serve``; the
    viewer lays it out by ``default_blueprint`` (e.g. :func:`~tactile_manip.interop.rerun_log.blueprint`).

    Raises:
        ValueError: none or several sinks asked for, or a port out of range.
        OSError: no display for a viewer to start, or the viewer or server did not listen on ``bind:port``.
    """
    if sum((save is not None, spawn, serve)) != 1:
        raise ValueError("rerun: give exactly one of --save F.rrd, --spawn or --serve")
    if not 0 < port < 65536:
        raise ValueError(f"--rerun-port: expected 1..65535, got {port}")
    rr = require_rerun("the Rerun view")
    rec = rr.RecordingStream(APPLICATION_ID)
    if recording_name:
        rec.send_recording_name(recording_name)
    if save is not None:
        rr.save(str(save), default_blueprint=default_blueprint, recording=rec)
        return LiveSink(rec, f"saving to {save}")
    url = grpc_url(bind, port)
    if _listening(grpc_host(bind), port):
        if serve:
            raise OSError(f"port {port} is taken on {grpc_host(bind)}; choose another with --rerun-port")
        rr.connect_grpc(url, default_blueprint=default_blueprint, recording=rec)  # a viewer runs there: use it
        return LiveSink(rec, f"viewer at {url}")
    if spawn and display_problem():
        raise OSError(display_problem())
    proc = _start(viewer_command(serve=serve, bind=bind, port=port))
    # a server goes with this process, SIGKILL included (a viewer is the user's window and stays)
    lifeline = Lifeline(groups=[proc.pid]) if serve and not _WINDOWS else None
    try:
        _wait_listening(bind, port, proc)
        rr.connect_grpc(url, default_blueprint=default_blueprint, recording=rec)
    except BaseException:  # not listening, or Ctrl-C meanwhile: the process we started goes too
        stop_process_group(proc)
        if lifeline is not None:
            lifeline.release()
        raise
    sink = LiveSink(rec, f"{'serving' if serve else 'viewer'} at {url}", process=proc, stop_process=serve,
                    lifeline=lifeline)
    if serve:
        sink.notes.append(f"connect a viewer with: rerun --connect {url}")
    if bind not in (LOCALHOST, "::1"):
        sink.notes.append(f"warning: listening on {bind} port {port}, reachable from other machines")
    return sink


def flush_within(recording, timeout_s: float, notes: list[str]) -> None:
    """Flush ``recording``, waiting at most ``timeout_s`` (rerun-sdk 0.24 has no timeout and waits for good): a
    stream interrupted mid-send (Ctrl-C, a stopped viewer) must not hold the command's exit; what was not sent
    in time is noted in ``notes``."""
    try:
        recording.flush(timeout_sec=timeout_s)
    except TypeError:  # an SDK without the timeout
        recording.flush()
    except Exception as e:  # noqa: BLE001 - rerun raises its own error when the timeout is reached
        notes.append(f"rerun: the last data was not flushed within {timeout_s:g} s ({type(e).__name__}: {e})")


def _start(cmd: list[str]) -> subprocess.Popen:
    """``cmd`` as the leader of a new process group (so the group can be stopped as one)."""
    group = ({"creationflags": subprocess.CREATE_NEW_PROCESS_GROUP} if _WINDOWS else {"start_new_session": True})
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            **group)


def stop_process_group(proc: subprocess.Popen, *, timeout_s: float = STOP_TIMEOUT_S) -> None:
    """Stop ``proc``, started by :func:`_start`, and every process of its group: SIGTERM, then SIGKILL to what is
    left once ``proc`` has exited or ``timeout_s`` has passed."""
    if _WINDOWS:  # the binary itself (see rerun_program): no group to stop
        if proc.poll() is None:
            proc.terminate()
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
        return
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)  # the group outlives its leader while a child of the leader runs
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            continue
    proc.poll()


def _wait_listening(bind: str, port: int, proc: subprocess.Popen) -> None:
    host = grpc_host(bind)
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise OSError(f"rerun exited with status {proc.returncode} before listening on {bind} port {port}"
                          f"{_exit_reason(bind, port, proc.args)}")
        if _listening(host, port):
            return
        time.sleep(0.1)
    raise OSError(f"rerun did not listen on {bind} port {port} within {START_TIMEOUT_S:.0f} s")


def _exit_reason(bind: str, port: int, cmd: list[str]) -> str:
    """Why a viewer or server may have exited: the port taken, the address not this machine's, or unknown."""
    family = socket.AF_INET6 if ":" in bind else socket.AF_INET
    with socket.socket(family) as s:
        try:
            s.bind((bind, port))
        except OSError as e:
            if e.errno == errno.EADDRINUSE:
                return ": the port is taken (choose another with --rerun-port)"
            if e.errno == errno.EADDRNOTAVAIL:
                return f": {bind} is not an address of this machine (see --bind)"
    return f" (run `{' '.join(cmd)}` to see its message)"


def _listening(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.2):
            return True
    except OSError:
        return False
