"""Connecting to a Ray cluster, or starting a private one on this machine, with one-line errors.

``address`` is what a user passes to ``--ray``: ``None`` or ``"local"`` starts a Ray instance on this machine
for the run (loopback only, no dashboard, no job submission), ``"auto"`` joins the cluster this machine is part of
(``ray start`` ran here), and ``"HOST:PORT"`` or ``"ray://HOST:PORT"`` joins that one. Before any work is sent,
a probe task checks that the cluster's workers can import ``tactile_manip``.

The processes of a private instance end with the run, however it ends: ``ray.shutdown()`` on the way out
(an error, Ctrl-C, SIGTERM), and a watchdog process for what that misses (Ray leaves its dashboard and
runtime-environment agents running when it is interrupted) and for a driver killed outright (SIGKILL, which
nothing can trap). The watchdog holds the read end of a pipe from the driver; when the pipe closes, the driver
is done or dead, and the watchdog stops every Ray process the driver started and their children.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from tactile_manip.errors import ClusterError
from tactile_manip.extras import require

LOCAL = "local"
LOOPBACK = "127.0.0.1"
# Every worker runs single-threaded numpy: the workers already fill the cores, and BLAS threads would fight.
_SINGLE_MACHINE = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"  # "0": Ray keeps every address of this node on loopback
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def check_address(address: str | None) -> str | None:
    """``address`` normalised (None for a private local instance); ValueError naming the accepted forms, or
    the scheme of a URL that is not ``ray://`` (an ``http://`` one is the dashboard's, which Ray does not join)."""
    if address is None or address == LOCAL:
        return None
    text = address.strip()
    if text == "auto":
        return text
    scheme = re.match(r"([A-Za-z][A-Za-z0-9+.-]*)://", text)
    if scheme and scheme.group(1).lower() in ("http", "https"):
        host = _url_host(text)
        raise ValueError(f"--ray: {address!r} is a URL of the Ray dashboard ({scheme.group(0).lower()}); Ray's "
                         f"client address is ray://{host}:10001, or give the GCS address {host}:6379")
    if scheme and scheme.group(1) != "ray":
        raise ValueError(f"--ray: unknown scheme '{scheme.group(0)}' in {address!r}; expected 'local', 'auto', "
                         "HOST:PORT or ray://HOST:PORT")
    host_port = text.removeprefix("ray://")
    host, sep, port = host_port.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"--ray: expected 'local', 'auto', HOST:PORT or ray://HOST:PORT, got {address!r}")
    return text


def _url_host(url: str) -> str:
    """The host of ``url`` as it goes in HOST:PORT (an IPv6 address in brackets); "HOST" when it names none."""
    from urllib.parse import urlsplit

    try:
        host = urlsplit(url).hostname
    except ValueError:
        host = None
    if not host:
        return "HOST"
    return f"[{host}]" if ":" in host else host


@contextlib.contextmanager
def ray_session(address: str | None, *, num_cpus: int | None = None,
                python_path: Sequence[str] = ()) -> Iterator[Any]:
    """The ``ray`` module, initialised for one run and shut down after it.

    Args:
        address: see the module docstring.
        num_cpus: CPUs of a private local instance (None: all of this machine's); ignored for a cluster.
        python_path: folders put first on the workers' ``PYTHONPATH`` (where a module the work needs was
            imported from; on a cluster they must exist on every node).

    Raises:
        MissingExtraError: ray is not installed here.
        ClusterError: the address cannot be reached, or the cluster's workers cannot import tactile_manip.
    """
    address = check_address(address)
    _prepare_environment(address)
    ray = require("ray", "running on a Ray cluster")
    if ray.is_initialized():
        raise ClusterError("Ray is already initialised in this process; call this outside another Ray session")
    env = dict(WORKER_ENV)
    if python_path:
        env["PYTHONPATH"] = os.pathsep.join([*python_path, *filter(None, [os.environ.get("PYTHONPATH")])])
    kwargs: dict[str, Any] = {"log_to_driver": False, "configure_logging": False, "runtime_env": {"env_vars": env}}
    if address is None:
        kwargs.update(num_cpus=num_cpus, include_dashboard=False, _node_ip_address=LOOPBACK)
    preflight(address)
    watchdog = _start_watchdog(ray) if address is None else None  # before ray.init: a kill during it is covered
    try:
        with _sigterm_through_ray() as keep_sigterm_handler:
            try:
                ray.init(address=address or LOCAL, **kwargs)  # "local": a new instance even where a cluster runs
            except Exception as e:  # Ray raises ConnectionError, RuntimeError or its own types when unreachable
                raise ClusterError(f"cannot reach the Ray cluster at {address or 'a new local instance'}: "
                                   f"{_first_line(e)} (is `ray start --head` running there? use --ray local for a "
                                   "private instance)") from e
            finally:
                keep_sigterm_handler()
            try:
                check_workers_import(ray, "tactile_manip")
                yield ray
            finally:
                ray.shutdown()
    finally:
        if watchdog is not None:
            _stop_watchdog(watchdog)


# The watchdog: argv is the driver's pid, Ray's package folder and the pids of the driver's children before Ray
# started. Every 0.2 s it notes the driver's new children that are Ray's (a "ray::" title, or a program or script
# in Ray's folder) and every descendant of what it noted; when its stdin closes, it stops them all.
_WATCHDOG = r"""
import os, sys, threading
import psutil

driver, ray_dir, before = int(sys.argv[1]), sys.argv[2], {int(p) for p in sys.argv[3:]}
me = os.getpid()
done = threading.Event()
threading.Thread(target=lambda: (sys.stdin.buffer.read(), done.set()), daemon=True).start()
tracked = {}

def is_ray(p):
    try:
        return p.name().startswith("ray::") or any(part.startswith(ray_dir) for part in p.cmdline())
    except psutil.Error:
        return False

def note():
    for pid, p in list(tracked.items()):
        if not p.is_running():  # gone: its pid may name another process by now
            del tracked[pid]
    children = {}
    for p in psutil.process_iter(["ppid"]):
        children.setdefault(p.info["ppid"], []).append(p)
    todo = [p for p in children.get(driver, []) if p.pid not in before and p.pid != me and is_ray(p)]
    todo += list(tracked.values())
    while todo:
        p = todo.pop()
        tracked.setdefault(p.pid, p)
        todo += [c for c in children.get(p.pid, []) if c.pid not in tracked]

while not done.wait(0.2):
    note()
note()
alive = [p for p in tracked.values() if p.is_running()]
for p in alive:
    try:
        p.terminate()
    except psutil.Error:
        pass
_, alive = psutil.wait_procs(alive, timeout=3)
for p in alive:
    try:
        p.kill()
    except psutil.Error:
        pass
psutil.wait_procs(alive, timeout=3)
"""
WATCHDOG_STOP_TIMEOUT_S = 15.0  # what the watchdog needs at most to stop what is left (3 s + 3 s), with margin


def _start_watchdog(ray: Any) -> subprocess.Popen | None:
    """The watchdog of a private instance, in a session of its own (a terminal's Ctrl-C does not reach it);
    None, with a warning, where psutil is missing."""
    import importlib.util

    if importlib.util.find_spec("psutil") is None:
        warnings.warn("psutil is not installed (extra 'ray'): a Ray instance of a killed run may leave processes "
                      "behind", RuntimeWarning, stacklevel=3)
        return None
    import psutil

    before = [str(p.pid) for p in psutil.Process().children()]
    ray_dir = os.path.dirname(os.path.abspath(ray.__file__)) + os.sep  # as Ray names its programs and scripts
    return subprocess.Popen([sys.executable, "-c", _WATCHDOG, str(os.getpid()), ray_dir, *before],
                            stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)


def _stop_watchdog(watchdog: subprocess.Popen) -> None:
    """Close the watchdog's pipe (it stops what Ray left running) and wait for it."""
    try:
        watchdog.stdin.close()
        watchdog.wait(timeout=WATCHDOG_STOP_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired):
        pass  # it goes on alone (or has gone); nothing here waits on it


@contextlib.contextmanager
def _sigterm_through_ray() -> Iterator[Callable[[], None]]:
    """The caller's SIGTERM handler through a Ray session; yields the function that puts it back after
    ``ray.init``, which replaces it (in Python, and in its C++ core, which exits with status 1).

    The CLI's handler raises an exception of its own, so that the ``finally`` blocks run and the exit status says
    SIGTERM; where Ray's core turns that exception into a plain KeyboardInterrupt, the handler's own exception is
    raised instead. Outside the main thread nothing changes.
    """
    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    previous = signal.getsignal(signal.SIGTERM)
    restore = signal.SIG_DFL if previous is None else previous  # None: set outside Python, cannot be put back
    raised: list[BaseException] = []

    def relay(signum, frame):
        try:
            previous(signum, frame)
        except BaseException as e:
            raised.append(e)
            raise

    handler = relay if callable(previous) else restore
    try:
        yield lambda: signal.signal(signal.SIGTERM, handler)
    except KeyboardInterrupt as e:
        if raised and e is not raised[-1]:
            raise raised[-1] from None
        raise
    finally:
        signal.signal(signal.SIGTERM, restore)


def _prepare_environment(address: str | None) -> None:
    """Ray settings that must be in the environment before ``import ray`` (a user's own settings win).

    - A private instance, or a cluster on this machine's loopback, stays on loopback: Ray otherwise replaces
      127.0.0.1 by the machine's network address; its single-machine mode keeps every address on loopback.
    - A cluster that ``ray start`` created with an authentication token (Ray >= 2.5x does by default) is joined
      with that token (``~/.ray/auth_token``).
    """
    if address is None or _is_loopback(_bootstrap_address(address)):
        if "ray" in sys.modules and os.environ.get(_SINGLE_MACHINE) != "0":
            warnings.warn("ray was imported before tactile_manip started its instance: Ray may listen on this "
                          f"machine's network address, not only on loopback (set {_SINGLE_MACHINE}=0 before "
                          "importing ray)", RuntimeWarning, stacklevel=3)
        os.environ.setdefault(_SINGLE_MACHINE, "0")
    if address is not None and (Path.home() / ".ray" / "auth_token").is_file():
        os.environ.setdefault("RAY_AUTH_MODE", "token")


def _bootstrap_address(address: str) -> str:
    """HOST:PORT that ``address`` names; for "auto", the cluster that ``ray start`` recorded on this machine."""
    if address == "auto":
        recorded = Path(tempfile.gettempdir()) / "ray" / "ray_current_cluster"
        try:
            return recorded.read_text().strip()
        except OSError:
            return os.environ.get("RAY_ADDRESS", "")
    return address.removeprefix("ray://")


def _is_loopback(host_port: str) -> bool:
    host = host_port.rpartition(":")[0].strip("[]")
    return host == "localhost" or host.startswith("127.") or host == "::1"


def preflight(address: str | None, timeout_s: float = 5.0) -> None:
    """Fail fast when nothing accepts TCP at a HOST:PORT ``address`` (Ray itself would retry for minutes)."""
    import socket

    if address in (None, "auto"):
        return
    host, _, port = address.removeprefix("ray://").rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s):
            pass
    except OSError as e:
        raise ClusterError(f"cannot reach the Ray cluster at {address}: {e.strerror or e} (is `ray start --head` "
                           "running there? use --ray local for a private instance)") from e


def check_workers_import(ray: Any, module: str) -> str:
    """The ``module``'s version as a cluster worker imports it; ClusterError when a worker cannot import it."""

    def probe(name: str) -> str:  # defined here so that Ray ships it by value, not as a reference into our package
        import importlib

        return str(getattr(importlib.import_module(name), "__version__", "?"))

    try:
        return ray.get(ray.remote(max_retries=0)(probe).remote(module), timeout=120)
    except Exception as e:
        raise ClusterError(f"the Ray cluster's workers cannot import {module} ({_first_line(e)}): install it on "
                           "every node (pip install tactile_manip), or start the cluster from an environment "
                           "that has it") from e


def cluster_cpus(ray: Any) -> int:
    """CPUs the connected cluster offers (at least 1)."""
    return max(1, int(ray.cluster_resources().get("CPU", 1)))


def _first_line(error: BaseException) -> str:
    lines = [ln.strip() for ln in str(error).splitlines() if ln.strip()]
    cause = error.__cause__
    if not lines and cause is not None:
        return _first_line(cause)
    text = lines[-1] if lines and lines[0].startswith("ray::") else (lines[0] if lines else type(error).__name__)
    return " ".join(text.split())[:300]

