"""The simulated eFlesh board's no-contact field against the real runs' raw field, and the time of one press.

    python -m benchmarks.eflesh_field_check
    python -m benchmarks.eflesh_field_check --data /path/to/eflesh_dev --presses 50

For the shipped ``eflesh`` board file (four N52 discs in the TPU cube over the five-chip board) the closed-form
field of the magnets at rest, in each chip's axes (firmware order centre, left, right, up, down), is set beside
each run's no-contact field: the baseline its publishers subtracted (``sensor.csv`` minus
``sensor_post_baselines.csv``, its median over the run; it moves by 13-60 uT rms within a run). Raw rows are no
measure of it: every row of the spatial run is a press, and the normal run's first rows hold a 3.4 kgf one. The z
components follow from the magnets' place in the board file; x and y depend on placement tolerances of the
magnets and chips and are listed only. Then one force-controlled press (a 6 mm sphere, 3 N, at the centre) is
timed: the median of ``--presses`` presses after one warm-up (which fills the kernel caches).

Prints markdown and writes docs/results/benchmarks/eflesh_field_check.json; asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.boards import load_board
from tactile_manip.sim.board_press import press
from tactile_manip.sim.board_skin import BoardSkin

CHIPS = ("centre", "left", "right", "up", "down")
DEFAULT_DATA = Path(os.environ.get("TACTILE_MANIP_EFLESH_DIR", Path(__file__).resolve().parents[2] / "shared"
                                   / "data" / "eflesh_dev"))


def idle_field_ut(run: Path) -> np.ndarray:
    """(5, 3) a run's no-contact field, chip axes, uT: the median of the baseline its publishers subtracted
    (raw ``sensor.csv`` minus ``sensor_post_baselines.csv``)."""
    raw = np.loadtxt(run / "sensor.csv", delimiter=",")[:, 1:16]
    subtracted = np.loadtxt(run / "sensor_post_baselines.csv", delimiter=",")[:, 1:16]
    return np.median(raw - subtracted, axis=0).reshape(5, 3)


def press_time_ms(skin: BoardSkin, presses: int) -> dict[str, float]:
    """Median and p90 wall time (ms) of one force-controlled press, after a warm-up press."""
    kwargs = {"tip": "sphere", "tip_diameter_mm": 6.0, "force_n": 3.0}
    press(skin, **kwargs)
    times = []
    for _ in range(presses):
        start = time.perf_counter()
        press(skin, **kwargs)
        times.append((time.perf_counter() - start) * 1e3)
    return {"median_ms": float(np.median(times)), "p90_ms": float(np.percentile(times, 90)), "presses": presses,
            "grid_px": skin.n, "pixel_mm": skin.pixel_mm}


def markdown(report: dict[str, Any]) -> str:
    lines = ["# eFlesh no-contact field: simulated vs real (chip axes, uT)", "",
             "| run | chip | sim x | sim y | sim z | real x | real y | real z | z sim/real |",
             "|---|---|---|---|---|---|---|---|---|"]
    sim = report["sim_ut"]
    for run, real in report["real_ut"].items():
        for i, name in enumerate(CHIPS):
            s, r = sim[name], real[name]
            lines.append(f"| {run} | {name} | {s[0]:.0f} | {s[1]:.0f} | {s[2]:.0f} | {r[0]:.0f} | {r[1]:.0f} | "
                         f"{r[2]:.0f} | {s[2] / r[2]:.2f} |")
    t = report["press"]
    lines += ["", f"One force-controlled press (6 mm sphere, 3 N, {t['grid_px']}x{t['grid_px']} px of "
                  f"{t['pixel_mm']:g} mm): median {t['median_ms']:.1f} ms, p90 {t['p90_ms']:.1f} ms "
                  f"over {t['presses']} presses."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA,
                        help="folder of the eFlesh runs (each a folder with sensor.csv)")
    parser.add_argument("--presses", type=int, default=20, help="presses timed")
    parser.add_argument("--out", default="docs/results/benchmarks/eflesh_field_check.json")
    args = parser.parse_args(argv)

    runs = sorted(p for p in args.data.glob("*") if (p / "sensor.csv").is_file())
    if not runs:
        parser.error(f"no run folder with a sensor.csv in {args.data}: pass --data or set TACTILE_MANIP_EFLESH_DIR")
    skin = BoardSkin(load_board("eflesh"))
    sim = skin.baseline_ut()
    report: dict[str, Any] = {
        "board": "eflesh", "real": "median of sensor.csv - sensor_post_baselines.csv",
        "sim_ut": {name: sim[i].round(1).tolist() for i, name in enumerate(CHIPS)},
        "real_ut": {run.name: {name: v.round(1).tolist() for name, v in zip(CHIPS, idle_field_ut(run))}
                    for run in runs},
        "press": press_time_ms(skin, args.presses),
        "machine": machine_info(),
    }
    publish(report, Path(args.out), markdown)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
