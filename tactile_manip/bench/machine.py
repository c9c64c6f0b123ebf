"""What a measurement was taken on: CPU, cores, load, interpreter and library versions, code version."""

from __future__ import annotations

import importlib.metadata
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.version import code_version

LIBRARIES = ("numpy", "scipy", "onnxruntime", "onnx", "torch", "roboticstoolbox-python", "matplotlib")


def cpu_model() -> str:
    """The CPU's model name from ``/proc/cpuinfo`` (Linux), else what ``platform`` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def usable_cores() -> int:
    """Cores this process may run on (its affinity mask where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def load_average() -> tuple[float, float, float] | None:
    """1, 5 and 15 minute load averages (None where the OS has none): a busy machine skews every timing."""
    try:
        return tuple(round(x, 2) for x in os.getloadavg())  # type: ignore[return-value]
    except (AttributeError, OSError):
        return None


def cpu_counters() -> dict[str, float] | None:
    """System-wide busy and stolen CPU seconds (``/proc/stat``) and this process's own CPU seconds (with its
    children), for :func:`other_load`; None where ``/proc/stat`` is missing."""
    try:
        fields = [float(x) for x in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
    except (OSError, ValueError, IndexError):
        return None
    tick = float(os.sysconf("SC_CLK_TCK"))
    user, nice, system, _idle, _iowait, irq, softirq, steal = (fields + [0.0] * 8)[:8]
    own = os.times()
    return {"busy_s": (user + nice + system + irq + softirq) / tick, "steal_s": steal / tick,
            "own_s": own.user + own.system + own.children_user + own.children_system,
            "wall_s": time.monotonic()}


def other_load(start: dict[str, float] | None, end: dict[str, float] | None) -> dict[str, float] | None:
    """Between two :func:`cpu_counters`: the cores other processes kept busy on average, and the share of
    CPU time the hypervisor took (steal). Both near 0 mean the timings are the machine's own."""
    if not start or not end or end["wall_s"] <= start["wall_s"]:
        return None
    wall = end["wall_s"] - start["wall_s"]
    other = (end["busy_s"] - start["busy_s"]) - (end["own_s"] - start["own_s"])
    return {"other_processes_cores": round(max(other, 0.0) / wall, 3),
            "steal_share": round((end["steal_s"] - start["steal_s"]) / (wall * usable_cores()), 4),
            "seconds": round(wall, 1)}


def library_versions(names: tuple[str, ...] = LIBRARIES) -> dict[str, str | None]:
    """Installed version of each distribution (None when it is not installed); imports nothing."""
    out: dict[str, str | None] = {}
    for name in names:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out


def machine_info() -> dict[str, Any]:
    """CPU model, core counts, load, interpreter and numpy/scipy versions, which path the pose stage runs (C
    kernel or numpy), code version, time of the run."""
    import scipy

    from tactile_manip.perception import pose_kernel

    return {"cpu_model": cpu_model(), "cpu_count": os.cpu_count(), "usable_cores": usable_cores(),
            "load_average": load_average(), "python": sys.version.split()[0], "numpy": np.__version__,
            "scipy": scipy.__version__, "pose_stage": pose_kernel.describe(), "platform": platform.platform(),
            "code_version": code_version(),
            "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
