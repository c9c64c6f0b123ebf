"""Export throughput (frames/s) per format, and what recording the per-frame streams costs a trial run.

    python -m benchmarks.bench_export                       # a 60 s recording, every installed format, 3 repeats
    python -m benchmarks.bench_export --seconds 10 --trials 0   # quick, no trial run

1. A recording of ``--seconds`` at 125 Hz (idle chips and a press, written with the recorder's own writer) is
   exported with :func:`tactile_manip.interop.export.export_source` to each format whose writer is installed
   (lerobot; rrd and mcap when their modules exist), ``--repeats`` times; the table gives the median wall
   time and frames per second end to end (reading the source included) and for the writer alone. The lerobot
   export is also timed with ``--depth bilinear`` (a depth image per frame, PNG-encoded).
2. With ``--trials N`` the README's scene (configs/scenes/reorient_sim.toml, every method) runs N trials with
   and without per-frame recording, alternately after one untimed warm-up run, and the table gives the wall time per trial and the
   frames files' size. Writes docs/results/benchmarks/export.json. It reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.interop.export import WRITERS, export_source, load_writer
from tactile_manip.interop.sources import read_source

RATE_HZ = 125.0


def make_recording(path: Path, seconds: float, seed: int = 0) -> Path:
    """A recording of ``seconds`` at 125 Hz: the simulated sensor's idle field, chip noise and one press."""
    from tactile_manip.wire.protocol import CountScale, encode_frame
    from tactile_manip.sensors.recording import RecordingWriter, recording_header
    from tactile_manip.sensors.simulated import SimulatedSensor

    rng = np.random.default_rng(seed)
    sensor = SimulatedSensor()
    scale = CountScale.from_chip(sensor.chip)
    idle = sensor.pair.to_reading(sensor.pair.baseline_field_ut)  # (4, 4, 3) uT
    n = int(round(seconds * RATE_HZ))
    with RecordingWriter(path, recording_header(sensor)) as out:
        for k in range(n):
            press = 150.0 * np.exp(-((k - n / 2) / 60.0) ** 2)
            field = idle + rng.normal(0.0, 2.0, idle.shape) + np.array([0.0, 0.0, press])
            out.write_frame(k / RATE_HZ, encode_frame(scale.to_counts(field.astype(np.float32)), seq=k,
                                                      t_mcu_us=int(k * 8000), status=0))
    return path


def time_exports(recording: Path, work: Path, repeats: int) -> list[dict[str, Any]]:
    frames = read_source(recording).frames
    rows = []
    cases = [(fmt, None) for fmt in WRITERS] + [("lerobot", "bilinear")]
    for fmt, depth in cases:
        try:
            writer = load_writer(fmt)
        except (ValueError, ImportError) as e:
            rows.append({"format": fmt, "depth": depth, "available": False, "why": str(e)})
            continue
        total, write_only = [], []
        for r in range(repeats):
            out = work / f"{fmt}-{depth}-{r}" if fmt == "lerobot" else work / f"{fmt}-{r}.{fmt}"
            t0 = time.perf_counter()
            export_source(recording, out, fmt=fmt, depth_model=depth)
            total.append(time.perf_counter() - t0)
            src = read_source(recording)
            if depth:
                from tactile_manip.interop.depth import add_depth

                add_depth(src.episodes, depth)
            t0 = time.perf_counter()
            writer(src.episodes, work / f"w-{fmt}-{depth}-{r}")
            write_only.append(time.perf_counter() - t0)
        t, w = statistics.median(total), statistics.median(write_only)
        rows.append({"format": fmt, "depth": depth, "available": True, "frames": frames, "export_s": round(t, 4),
                     "export_fps": round(frames / t, 1), "writer_s": round(w, 4), "writer_fps": round(frames / w, 1),
                     "bytes": _size(work / (f"{fmt}-{depth}-0" if fmt == "lerobot" else f"{fmt}-0.{fmt}"))})
    return rows


def time_trials(n: int, work: Path, rounds: int) -> dict[str, Any]:
    """Wall time per trial of the README's scene with and without frame recording (alternating runs)."""
    from tactile_manip.trials.runner import run_trials
    from tactile_manip.trials.scene import load_scene

    scene = dataclasses.replace(load_scene("configs/scenes/reorient_sim.toml"), trials=n)
    per_trial: dict[bool, list[float]] = {True: [], False: []}
    size, files, frames = 0, 0, 0
    run_trials(scene, work / "warm-up", scene_path="configs/scenes/reorient_sim.toml", progress=False, frames=False)
    for r in range(rounds):
        for on in (False, True) if r % 2 == 0 else (True, False):
            out = work / f"trials-{on}-{r}"
            t0 = time.perf_counter()
            run_trials(scene, out, scene_path="configs/scenes/reorient_sim.toml", progress=False, frames=on)
            per_trial[on].append((time.perf_counter() - t0) / (n * len(scene.methods)))
            if on and r == 0:
                paths = list((out / "frames").glob("*.tmframes"))
                size, files = sum(p.stat().st_size for p in paths), len(paths)
                frames = read_source(out).frames
    off, on = statistics.median(per_trial[False]), statistics.median(per_trial[True])
    return {"trials": n, "methods": len(scene.methods), "rounds": rounds, "s_per_trial_without": round(off, 4),
            "s_per_trial_with": round(on, 4), "overhead_percent": round(100 * (on - off) / off, 1),
            "frames_files": files, "frames": frames, "bytes": size}


def _size(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [f"Export of a {report['seconds']:g} s recording ({report['frames']} frames at 125 Hz); "
             f"{m.get('cpu_model', '?')}, median of {report['repeats']}", "",
             "| format | depth | export s | export frames/s | writer s | writer frames/s | output MB |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for r in report["exports"]:
        if not r["available"]:
            lines.append(f"| {r['format']} | {r['depth'] or '-'} | not installed | | | | |")
            continue
        lines.append(f"| {r['format']} | {r['depth'] or '-'} | {r['export_s']:.3f} | {r['export_fps']:,.0f} | "
                     f"{r['writer_s']:.3f} | {r['writer_fps']:,.0f} | {r['bytes'] / 1e6:.2f} |")
    t = report.get("trials")
    if t:
        lines += ["", f"Trial runs ({t['trials']} trials x {t['methods']} methods, median of {t['rounds']} runs each):",
                  "", "| frames recorded | s per trial | frames files | frames | bytes |", "|---|---:|---:|---:|---:|",
                  f"| no (`--no-frames`) | {t['s_per_trial_without']:.4f} | 0 | 0 | 0 |",
                  f"| yes (default) | {t['s_per_trial_with']:.4f} | {t['frames_files']} | {t['frames']} | "
                  f"{t['bytes']:,} |", "", f"overhead: {t['overhead_percent']:+.1f} % per trial"]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="length of the exported recording, s (60)")
    parser.add_argument("--repeats", type=int, default=3, help="exports per format (3)")
    parser.add_argument("--trials", type=int, default=10, help="trials per run for the recording cost (10; 0: skip)")
    parser.add_argument("--rounds", type=int, default=3, help="runs with and without frames each (3)")
    parser.add_argument("--out", default="docs/results/benchmarks/export.json", help="JSON report")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_export-") as tmp:
        work = Path(tmp)
        rec = make_recording(work / "rec.tmrec", args.seconds)
        report = {"machine": machine_info(), "seconds": args.seconds, "frames": read_source(rec).frames,
                  "repeats": args.repeats, "exports": time_exports(rec, work, args.repeats)}
        if args.trials > 0:
            report["trials"] = time_trials(args.trials, work, args.rounds)
    publish(report, args.out, markdown)


if __name__ == "__main__":
    main()
