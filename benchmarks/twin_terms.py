"""What each of the twin's terms buys on the spatial eFlesh run, forward and read backwards.

    python -m benchmarks.twin_terms --layout upside_down      # eflesh.toml with the right-handed chip layout
    python -m benchmarks.twin_terms --board my-cube.toml --runs /path/to/runs --out /tmp/terms.json

The chronological 80/20 split of ``tactile-manip import``: ``fit_twin`` (what ``fit-board`` runs, every label of
the first 80 %, 800 presses of them) fits the board; each stage with free readouts (``readout``: the point-load
kernel; ``base``: with the press's image in the rigid base; ``cells``: with the printed lattice's nodes) is scored
on the last 20 %:

- forward: the explained variance of the test readings given the logged pose, overall and per channel;
- read backwards: the test presses placed by the twin alone (``twin_prior.twin_targets``, the labeller's reading of
  a bank: the twin's readings at a grid of stage poses, 0.5 mm over the pad and 4 mm beyond, 12 depths to 6 mm),
  2-D position RMSE (mm) against the stage's.

And how faithful a twin must be to place well: the readout stage's twin plus a thin-plate smoothing of its residual
over (x, y, 3 z) fitted on the first 80 % (smoothing 1e4 to 10: a smaller one follows finer detail), each scored the
same two ways. It measures; it asserts nothing. Writes docs/results/twin/twin_terms.{json,md} (``--out``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from benchmarks.twin_protocol import CONTACT_Z_MM, DEFAULT_RUNS, LABELS, run_folders

SMOOTHING = (1e4, 1e3, 1e2, 10.0)  # of the residual's thin-plate map: what finer detail buys


def spatial_rows(board: Any, run: Path) -> Any:
    """The run's rows as ``fit-board`` reads them (chip axes, uT; the pose; the split)."""
    from tactile_manip.commands.twin_logs import probe_rows

    return probe_rows(board, str(run / "sensor_post_baselines.csv"), str(run / "states.csv"),
                      LABELS["spatial"].split(","), 0.8)


def placed_rmse(readings: np.ndarray, pose: np.ndarray, bank: np.ndarray, grid: np.ndarray) -> float:
    """2-D RMSE (mm) of ``readings`` (N, C, 3) placed on a bank of readings (G, C, 3) made at ``grid`` (G, 3)."""
    from tactile_manip.learning.contact.twin_prior import twin_targets

    placed = twin_targets(readings, bank, grid[:, :2])
    return float(np.sqrt(np.mean(np.sum((placed - pose[:, :2]) ** 2, axis=1))))


def score(predict: Any, rows: Any, test: np.ndarray, grid: np.ndarray, hours: np.ndarray) -> dict[str, Any]:
    """Forward EV and the place read backwards, for ``predict(stage poses, hours)`` -> (N, C, 3) readings."""
    from tactile_manip.sim.twin_fit import explained_variance

    ev, per = explained_variance(rows.readings_ut[test], predict(rows.stage_xyz_mm[test], hours[test]))
    rmse = placed_rmse(rows.readings_ut[test], rows.stage_xyz_mm[test], predict(grid, None), grid)
    return {"test_ev": round(ev, 4), "test_ev_per_channel": [round(v, 3) for v in per],
            "placed_rmse_mm": round(rmse, 3)}


def smoothed(twin: Any, rows: Any, train: np.ndarray, hours: np.ndarray, smoothing: float) -> Any:
    """``twin``'s readings plus a thin-plate map of its residual on the ``train`` rows."""
    from scipy.interpolate import RBFInterpolator

    def coords(pose: np.ndarray) -> np.ndarray:
        return np.c_[pose[:, :2], 3.0 * pose[:, 2]]

    residual = (rows.readings_ut[train] - twin.readings_ut(rows.stage_xyz_mm[train], hours[train]))
    fit = RBFInterpolator(coords(rows.stage_xyz_mm[train]), residual.reshape(len(residual), -1),
                          kernel="thin_plate_spline", smoothing=smoothing, neighbors=200, degree=1)
    return lambda pose, h: twin.readings_ut(pose, h) + fit(coords(pose)).reshape(len(pose), -1, 3)


def main(argv: list[str] | None = None) -> int:
    from tactile_manip.boards import load_board
    from tactile_manip.commands.twin_logs import rest_field
    from tactile_manip.sim.twin import BoardTwin, stage_grid
    from tactile_manip.sim.twin_fit import PressLog, fit_twin

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--board", default="eflesh", metavar="NAME|FILE", help="the board file to fit (default eflesh)")
    p.add_argument("--layout", default=None, help="fit the board with one of benchmarks.eflesh_chip_layout's chip "
                   "layouts instead of its own (e.g. upside_down: the right-handed chips over discs polarised -z)")
    p.add_argument("--runs", type=Path, default=DEFAULT_RUNS, help="folder holding a spatial_* run")
    p.add_argument("--rows", type=int, default=800, help="presses fitted (fit-board's default)")
    p.add_argument("--out", type=Path, default=Path("docs/results/twin/twin_terms.json"))
    args = p.parse_args(argv)
    run = run_folders(args.runs)["spatial"]
    board = load_board(args.board)
    if args.layout:
        from benchmarks.eflesh_chip_layout import layouts

        board = layouts(board)[args.layout][0]
    rows = spatial_rows(board, run)
    hours = (rows.time_s - rows.time_s[0]) / 3600.0
    train, test = np.flatnonzero(rows.split == "train"), np.flatnonzero(rows.split == "test")
    test = test[rows.stage_xyz_mm[test, 2] < CONTACT_Z_MM]
    chosen = train[np.unique(np.linspace(0, len(train) - 1, min(args.rows, len(train))).astype(int))]
    rest, _ = rest_field(board, run / "sensor.csv", run / "sensor_post_baselines.csv", 0.8)
    start = time.perf_counter()
    fit = fit_twin(board, PressLog(rows.stage_xyz_mm[chosen], rows.readings_ut[chosen], hours[chosen]), rest_ut=rest,
                   report=lambda line: print(line, flush=True))
    report: dict[str, Any] = {"board": str(args.board), "layout": args.layout or "the board file's", "run": run.name,
                              "fit_seconds": round(time.perf_counter() - start, 1),
                              "fitted_rows": len(chosen), "test_presses": len(test), "stages": {},
                              "smoothed_residual": {}, "machine": machine_info()}
    for stage, fitted in fit.stage_boards.items():
        twin = BoardTwin(fitted)
        grid = stage_grid(fitted)
        report["stages"][stage] = {**score(twin.readings_ut, rows, test, grid, hours),
                                   "fit_ev": fit.stages[stage]["ev"], "note": fit.stages[stage].get("note", "")}
        print(f"{stage}: test EV {report['stages'][stage]['test_ev']:.4f}, placed "
              f"{report['stages'][stage]['placed_rmse_mm']:.2f} mm", flush=True)
    readout = BoardTwin(fit.stage_boards["readout"])
    grid = stage_grid(fit.stage_boards["readout"])
    for smoothing in SMOOTHING:
        line = score(smoothed(readout, rows, train, hours, smoothing), rows, test, grid, hours)
        report["smoothed_residual"][f"{smoothing:g}"] = line
        print(f"readout + residual map, smoothing {smoothing:g}: test EV {line['test_ev']:.4f}, placed "
              f"{line['placed_rmse_mm']:.2f} mm", flush=True)
    publish(report, args.out, markdown)
    args.out.with_suffix(".md").write_text(markdown(report).strip() + "\n")
    return 0


def markdown(report: dict[str, Any]) -> str:
    lines = [f"# What the twin's terms buy ({report['run']}, board {Path(report['board']).stem}, chip layout "
             f"{report.get('layout', 'of the file')}; fitted on "
             f"{report['fitted_rows']} presses of the first 80 %, scored on the {report['test_presses']} test presses)",
             "", "| stage | EV, fitted rows | EV, test tail | placed by the twin alone (mm RMSE) | |",
             "|---|---|---|---|---|"]
    for stage, row in report["stages"].items():
        lines.append(f"| {stage} | {row['fit_ev']:.3f} | {row['test_ev']:.3f} | {row['placed_rmse_mm']:.2f} | "
                     f"{row['note']} |")
    lines += ["", "The readout stage's twin plus a thin-plate map of its residual (fitted on the first 80 %):", "",
              "| smoothing | EV, test tail | placed (mm RMSE) |", "|---|---|---|"]
    lines += [f"| {k} | {row['test_ev']:.3f} | {row['placed_rmse_mm']:.2f} |"
              for k, row in report["smoothed_residual"].items()]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
