"""Where a live Rerun recording goes: a ``.rrd`` file, a viewer we start, or a gRPC server on this machine.

The viewer and the server are the ``rerun`` command of the installed rerun-sdk (``python -m rerun``), started
with ``--bind`` so they listen on 127.0.0.1 unless the caller asks for another address: the SDK's own
``rr.spawn`` and ``rr.serve_grpc`` listen on every interface. The logging process then connects to it over
gRPC.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from tactile_manip.interop.rerun_log import APPLICATION_ID, require_rerun

DEFAULT_PORT = 9876          # Rerun's own default gRPC port
LOCALHOST = "127.0.0.1"
START_TIMEOUT_S = 20.0       # a cold viewer or server takes a few seconds to listen


def viewer_command(*, serve: bool, bind: str, port: int) -> list[str]:
    """The ``rerun`` command line of a viewer (``serve=False``) or a viewer-less gRPC server, on ``bind:port``."""
    cmd = [sys.executable, "-m", "rerun", "--bind", bind, "--port", str(port)]
    return cmd + ["--serve-grpc"] if serve else cmd


def grpc_url(host: str, port: int) -> str:
    """The proxy URL an SDK or a viewer connects to."""
    host = LOCALHOST if host in ("0.0.0.0", "::", "") else host
    return f"rerun+http://{host}:{port}/proxy"


@dataclass
class LiveSink:
    """An open recording and the process behind it (None for a file); :meth:`close` flushes and stops it.

    A spawned viewer is left running (it is the user's window); a server this process started is stopped.
    """

    recording: object
    description: str
    process: subprocess.Popen | None = None
    stop_process: bool = False
    notes: list[str] = field(default_factory=list)

    def close(self) -> None:
        try:
            self.recording.flush()
            self.recording.disconnect()
        finally:
            if self.process is not None and self.stop_process and self.process.poll() is None:
                self.process.terminate()
                try:
                    self.process.wait(timeout=5.0)
                except subprocess.TimeoutExpired:
                    self.process.kill()

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
        OSError: the viewer or server did not start listening on ``bind:port``.
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
    cmd = viewer_command(serve=serve, bind=bind, port=port)
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=spawn)  # a viewer outlives us; a server is ours to stop
    try:
        _wait_listening(grpc_host(bind), port, proc)
    except OSError:
        if proc.poll() is None:
            proc.terminate()
        raise
    rr.connect_grpc(url, default_blueprint=default_blueprint, recording=rec)
    sink = LiveSink(rec, f"{'serving' if serve else 'viewer'} at {url}", process=proc, stop_process=serve)
    if serve:
        sink.notes.append(f"connect a viewer with: rerun --connect {url}")
    if bind not in (LOCALHOST, "localhost", "::1"):
        sink.notes.append(f"warning: listening on {bind}:{port}, reachable from other machines")
    return sink


def grpc_host(bind: str) -> str:
    """The address to reach a server bound to ``bind`` from this machine."""
    return LOCALHOST if bind in ("0.0.0.0", "::", "") else bind


def _wait_listening(host: str, port: int, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise OSError(f"rerun exited with status {proc.returncode} before listening on {host}:{port} "
                          f"(is the port taken? try --rerun-port)")
        if _listening(host, port):
            return
        time.sleep(0.1)
    raise OSError(f"rerun did not listen on {host}:{port} within {START_TIMEOUT_S:.0f} s")


def _listening(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.2):
            return True
    except OSError:
        return False
