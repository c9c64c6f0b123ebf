"""Connecting to a Ray cluster, or starting a private one on this machine, with one-line errors.

``address`` is what a user passes to ``--ray``: ``None`` or ``"local"`` starts a Ray instance on this machine
for the run (loopback only, no dashboard, no job submission), ``"auto"`` joins the cluster this machine is part of
(``ray start`` ran here), and ``"HOST:PORT"`` or ``"ray://HOST:PORT"`` joins that one. Before any work is sent,
a probe task checks that the cluster's workers can import ``tactile_manip``.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import warnings
from collections.abc import Iterator
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
    """``address`` normalised (None for a private local instance); ValueError naming the accepted forms."""
    if address is None or address == LOCAL:
        return None
    text = address.strip()
    if text == "auto":
        return text
    host_port = text.removeprefix("ray://")
    host, sep, port = host_port.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"--ray: expected 'local', 'auto', HOST:PORT or ray://HOST:PORT, got {address!r}")
    return text


@contextlib.contextmanager
def ray_session(address: str | None, *, num_cpus: int | None = None) -> Iterator[Any]:
    """The ``ray`` module, initialised for one run and shut down after it.

    Args:
        address: see the module docstring.
        num_cpus: CPUs of a private local instance (None: all of this machine's); ignored for a cluster.

    Raises:
        MissingExtraError: ray is not installed here.
        ClusterError: the address cannot be reached, or the cluster's workers cannot import tactile_manip.
    """
    address = check_address(address)
    _prepare_environment(address)
    ray = require("ray", "running on a Ray cluster")
    if ray.is_initialized():
        raise ClusterError("Ray is already initialised in this process; call this outside another Ray session")
    kwargs: dict[str, Any] = {"log_to_driver": False, "configure_logging": False,
                              "runtime_env": {"env_vars": dict(WORKER_ENV)}}
    if address is None:
        kwargs.update(num_cpus=num_cpus, include_dashboard=False, _node_ip_address=LOOPBACK)
    preflight(address)
    try:
        ray.init(address=address or LOCAL, **kwargs)  # "local": a new instance even where a cluster runs
    except Exception as e:  # Ray raises ConnectionError, RuntimeError or its own types for an unreachable address
        raise ClusterError(f"cannot reach the Ray cluster at {address or 'a new local instance'}: "
                           f"{_first_line(e)} (is `ray start --head` running there? use --ray local for a "
                           "private instance)") from e
    try:
        check_workers_import(ray, "tactile_manip")
        yield ray
    finally:
        ray.shutdown()


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

