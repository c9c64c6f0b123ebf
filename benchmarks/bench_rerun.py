"""Rerun logging cost per frame at the sensor's 125 Hz, and the .rrd / MCAP export throughput in frames per second.

Run from the repository root (extras ``viz`` and ``mcap``)::

    python -m benchmarks.bench_rerun [--seconds 10] [--frames 5000] [--repeats 3] [--out docs/results/benchmarks/rerun.json]

Logging: :class:`~tactile_manip.interop.rerun_log.RerunLogger` writes to a ``.rrd`` file (what ``view --rerun
--save`` does) the three timelines and the field arrows of every frame, sent column-wise 12 frames at a time,
and the Bz heat map of every 5th frame (its defaults); the second row adds the angle, confidence and a
200x200 depth image at 10 Hz (``view``'s default ``--estimate-hz``); the last row sends each frame on its own
with the heat map of every frame (``batch_frames=1, heatmap_every=1``), for comparison. "Paced"
logs at 125 Hz for ``--seconds`` and divides the process's CPU time (every thread: rerun encodes and writes
on its own threads) by the wall time, minus the same paced loop without logging: the share of one core the
logging takes. "Back to back" logs ``--frames`` frames as fast as it can: CPU and wall time per frame. The
goal is under 10 % of a core at 125 Hz. Export: a 10 s episode (1250 frames, estimates on every frame,
joints, a 200x200 depth image at 10 Hz) through ``write_rrd`` and ``write_mcap`` (CDR, the rosbag2 profile,
JSON), best of ``--repeats``. It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.interop.frames import PHASES, Episode, Frame

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "docs" / "results" / "benchmarks" / "rerun.json"
RATE_HZ = 125.0
ESTIMATE_EVERY = 12          # frames between estimates: 125 / 12 = 10.4 Hz
GOAL_PERCENT = 10.0
BOTH = ("paced", "back to back")
# label, estimates at 10 Hz, RerunLogger's batch_frames and heatmap_every, modes
CASES = (("field", False, 12, 5, BOTH),
         ("field + estimates, 200x200 depth at 10 Hz", True, 12, 5, BOTH),
         ("field, each frame sent alone, heat map of every frame", False, 1, 1, ("paced",)))


def _fields(n: int) -> np.ndarray:
    return np.random.default_rng(0).normal(0, 80, (n, 4, 4, 3)).astype(np.float32)


def _depth() -> np.ndarray:
    return np.random.default_rng(1).uniform(0, 1.5, (200, 200)).astype(np.float32)


def _paced(seconds: float, log) -> dict[str, float]:
    """Call ``log(i)`` at 125 Hz for ``seconds``; process CPU over wall time."""
    period = 1.0 / RATE_HZ
    n = int(seconds * RATE_HZ)
    cpu0, t0 = time.process_time(), time.perf_counter()
    for i in range(n):
        log(i)
        wait = t0 + (i + 1) * period - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
    wall = time.perf_counter() - t0
    return {"frames": n, "wall_s": wall, "cpu_s": time.process_time() - cpu0}


def bench_logging(seconds: float, frames: int) -> dict[str, Any]:
    import rerun as rr

    from tactile_manip.interop.rerun_log import RerunLogger
    from tactile_manip.boards import load_board

    fields, depth = _fields(max(frames, int(seconds * RATE_HZ))), _depth()
    idle = _paced(seconds, lambda i: fields[i].sum())  # the loop itself, without logging
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, estimates, batch, heat, modes in CASES:
            for mode in modes:
                rec = rr.RecordingStream("bench_rerun")
                rr.save(str(Path(tmp) / f"{len(rows)}.rrd"), recording=rec)
                logger = RerunLogger(rec, layout=load_board("supermag-4x4"), batch_frames=batch, heatmap_every=heat)

                def log(i: int, logger=logger, estimates=estimates) -> None:
                    logger.log_frame(fields[i], sensor_time_s=i / RATE_HZ, host_time_s=1000.0 + i / RATE_HZ, frame=i)
                    if estimates and i % ESTIMATE_EVERY == 0:
                        logger.log_estimate(angle_rad=0.3, confidence=0.9, depth_mm=depth)

                if mode == "paced":
                    r = _paced(seconds, log)
                else:
                    cpu0, t0 = time.process_time(), time.perf_counter()
                    for i in range(frames):
                        log(i)
                    r = {"frames": frames, "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - cpu0}
                t_flush = time.process_time()
                logger.flush()
                rec.flush()
                rec.disconnect()
                r["flush_cpu_s"] = time.process_time() - t_flush
                cpu = r["cpu_s"] + r["flush_cpu_s"]
                if mode == "paced":
                    r["core_percent"] = 100.0 * (cpu - idle["cpu_s"] * r["wall_s"] / idle["wall_s"]) / r["wall_s"]
                r["cpu_us_per_frame"] = 1e6 * cpu / r["frames"]
                r["wall_us_per_frame"] = 1e6 * r["wall_s"] / r["frames"]
                rows[f"{label} ({mode})"] = r
    return {"idle_loop": idle, "rows": rows, "rerun_sdk": rr.__version__}


def episode(seconds: float = 10.0) -> Episode:
    """A trial-like episode: every stream filled, depth at 10 Hz."""
    rng = np.random.default_rng(2)
    n = int(seconds * RATE_HZ)
    fields, depth = _fields(n), _depth()
    frames = [Frame(t_s=i / RATE_HZ, host_time_s=1000.0 + i / RATE_HZ, field_ut=fields[i],
                    angle_rad=float(rng.uniform(-1.5, 1.5)), confidence=float(rng.uniform()),
                    joints_rad=rng.uniform(-2, 2, 7), gripper_width_m=0.03, target_angle_rad=0.0,
                    phase=PHASES[1 + 4 * i // n], depth_mm=depth if i % ESTIMATE_EVERY == 0 else None)
              for i in range(n)]
    return Episode(index=0, task="bench", fps=RATE_HZ, frames=frames, meta={"layout": "supermag-4x4"})


def bench_export(repeats: int) -> dict[str, Any]:
    from tactile_manip.interop.mcap_export import write_mcap
    from tactile_manip.interop.rerun_export import write_rrd

    ep = episode()
    writers = {"rrd (write_rrd)": lambda out: write_rrd([ep], out),
               "mcap, CDR (write_mcap)": lambda out: write_mcap([ep], out),
               "mcap, rosbag2 profile (--ros2)": lambda out: write_mcap([ep], out, ros2=True),
               "mcap, JSON": lambda out: write_mcap([ep], out, encoding="json")}
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, write in writers.items():
            best = math.inf
            for k in range(repeats):
                out = Path(tmp) / f"{len(rows)}-{k}.bin"
                t0 = time.perf_counter()
                write(out)
                best = min(best, time.perf_counter() - t0)
            rows[name] = {"frames": len(ep.frames), "best_s": best, "frames_per_s": len(ep.frames) / best,
                          "file_mb": out.stat().st_size / 1e6}
    return rows


def markdown(report: dict[str, Any]) -> str:
    m, lg = report["machine"], report["logging"]
    lines = [f"Machine: {m['cpu_model']}, {m['usable_cores']}/{m['cpu_count']} cores, load {m['load_average']}, "
             f"Python {m['python']}, rerun-sdk {lg['rerun_sdk']}, code {m['code_version']}", "",
             "| Rerun logging at 125 Hz | frames | CPU per frame | wall per frame | share of one core |",
             "|---|---|---|---|---|"]
    for name, r in lg["rows"].items():
        share = f"{r['core_percent']:.2f} % (goal < {GOAL_PERCENT:g} %)" if "core_percent" in r else ""
        lines.append(f"| {name} | {r['frames']} | {r['cpu_us_per_frame']:.0f} us | {r['wall_us_per_frame']:.0f} us "
                     f"| {share} |")
    lines += ["", "| export of a 10 s episode | frames | best time | frames / s | file |", "|---|---|---|---|---|"]
    for name, r in report["export"].items():
        lines.append(f"| {name} | {r['frames']} | {r['best_s']:.3f} s | {r['frames_per_s']:.0f} | "
                     f"{r['file_mb']:.2f} MB |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench_rerun", description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0, help="length of each paced logging run, s (10)")
    p.add_argument("--frames", type=int, default=5000, help="frames of each back-to-back logging run (5000)")
    p.add_argument("--repeats", type=int, default=3, help="export runs per writer; the best is kept (3)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON report path")
    args = p.parse_args(argv)
    if args.seconds <= 0 or args.frames < 1 or args.repeats < 1:
        p.error("--seconds must be > 0, --frames and --repeats >= 1")
    report = {"machine": machine_info(), "settings": vars(args) | {"out": str(args.out)},
              "logging": bench_logging(args.seconds, args.frames), "export": bench_export(args.repeats)}
    worst = max(r["core_percent"] for r in report["logging"]["rows"].values() if "core_percent" in r)
    report["goal_core_percent"], report["goal_met"] = GOAL_PERCENT, worst < GOAL_PERCENT
    publish(report, args.out, markdown)
    return 0


if __name__ == "__main__":
    sys.exit(main())
