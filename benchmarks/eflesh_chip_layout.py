"""Which layout of the five chips the eFlesh runs ask for: the board file's former turns, those with the right and
down chips turned half a turn, their mirror image, left-handed chips, or those chips upside down over reversed
discs (what tactile_manip/boards/eflesh.toml holds since this comparison).

    python -m benchmarks.eflesh_chip_layout
    python -m benchmarks.eflesh_chip_layout --data /path/to/eflesh_dev --rows 400

The twin fitted to the spatial run (``tactile-manip fit-board``, docs/results/eflesh/twin) reads every chip as a
mirror image of the pad's axes: each fitted readout is a signed axis swap with z kept, so its determinant is -1,
and no turn of a chip is. A mirror image of the whole rig and board gives the same readings (the discs are
z-polarised, so the mirrored discs' field is the mirror of their field), so the runs say only this much: either
each chip reads a left-handed frame at the file's places, or the board is the file's mirror image (right-handed
chips; seen as the file has it, the up and down chips trade places and the right and down chips turn half a
turn; the rig's axes then meet the pad's as a mirror image). Turning the right and down chips alone, at the
file's places, is neither. A reading is the chip's axes dotted with the field, and reversing every disc's
polarisation reverses the field, so the left-handed chips' axes negated (each a proper turn, det +1: a chip read
upside down, through its board) over discs polarised -z read exactly what the left-handed chips read over the
file's discs: right-handed chips at the file's places, with no mirror between rig and pad (``upside_down``, the
layout the board file now holds; the others are built from the turns it held before, ``former_file``).
Each layout is scored on what does not depend on the rig at all and on the presses:

- **rest field**: the median of the logger's baseline (``sensor.csv`` minus ``sensor_post_baselines.csv``) over
  each run's first 80 %, against four equal discs on a rigid square (its centre, turn, depth, side and the discs'
  strength fitted, several starts): rms residual over the 15 channels and in-plane alone, uT;
- **presses** (spatial run): the board's chip axes held, one gain per chip, the discs' places, depth and strength
  free, the rig frame and press kernel fitted (the rig's turn and mirror searched) on ``--rows`` of the first 80 %
  of the rows (:mod:`tactile_manip.sim.twin_fit`, stage ``file`` with the magnets freed, rest field left out);
  explained variance on those rows and on the last 20 %.

Prints markdown and writes docs/results/eflesh/twin/chip_layout.json; asserts nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from benchmarks._common import machine_info, publish
from tactile_manip.boards import load_board
from tactile_manip.boards.identity import TURNS_BEFORE_RECORDS_DEG
from tactile_manip.boards.load import Board
from tactile_manip.boards.spec import ChipSpec
from tactile_manip.commands.twin_logs import probe_rows, rest_field
from tactile_manip.sim import twin_fit
from tactile_manip.sim.twin import Magnets, board_magnets, discs_field_pad_ut

DEFAULT_DATA = Path(os.environ.get("TACTILE_MANIP_EFLESH_DIR", Path(__file__).resolve().parents[2] / "shared"
                                   / "data" / "eflesh_dev"))
SPATIAL, NORMAL = "spatial_20250316_155729", "normal_20250401_014340"
TRAIN_FRACTION = 0.8
# the twin's fitted chip readouts (pad field -> chip reading: chip_turns_found in docs/results/eflesh/twin/spatial.toml)
# as the pad direction each chip axis reads (the readouts' rows)
FIT_READOUT_AXES = (("-y", "-x", "+z"), ("-y", "-x", "+z"), ("+x", "-y", "+z"), ("+y", "+x", "+z"),
                    ("-x", "+y", "+z"))


def former(board: Board) -> Board:
    """``board`` (the eflesh file) with the chip turns and discs its file gave before the layout was fitted: the
    AnySkin visualiser's turns (:data:`~tactile_manip.boards.identity.TURNS_BEFORE_RECORDS_DEG`) over discs
    polarised +z."""
    assert board.body is not None
    chips = tuple(dataclasses.replace(c, axes=None, rotation_deg=turn)
                  for c, turn in zip(board.chips, TURNS_BEFORE_RECORDS_DEG["eflesh"], strict=True))
    discs = dataclasses.replace(board.body, magnets=tuple(
        dataclasses.replace(m, polarisation_t=tuple(abs(v) for v in m.polarisation_t)) for m in board.body.magnets))
    return dataclasses.replace(board, chips=chips, body=discs)


def layouts(board: Board) -> dict[str, tuple[Board, str]]:
    """The layouts scored, by key (with a description), all at ``board``'s chip places (the eflesh file's): the
    former file's turns (:func:`former`), those with the right and down chips half a turn round, their mirror image
    (up and down chips' places traded, right and down chips half a turn round), the twin's left-handed chips, and
    those chips upside down over discs polarised -z (what the file now holds)."""
    board = former(board)
    chips = board.chips

    def turned(i: int) -> ChipSpec:
        return dataclasses.replace(chips[i], rotation_deg=(chips[i].rotation_deg + 180.0) % 360.0)

    half = tuple(turned(i) if i in (2, 4) else c for i, c in enumerate(chips))
    mirror = list(half)
    for i, j in ((3, 4), (4, 3)):
        mirror[i] = dataclasses.replace(half[i], position_mm=chips[j].position_mm, cell=chips[j].cell)
    left_handed = tuple(ChipSpec(cell=c.cell, position_mm=c.position_mm, axes=a)
                        for c, a in zip(chips, FIT_READOUT_AXES))
    upside_down = tuple(ChipSpec(cell=c.cell, position_mm=c.position_mm, axes=tuple(negated(n) for n in a))
                        for c, a in zip(chips, FIT_READOUT_AXES))
    assert board.body is not None
    reversed_discs = dataclasses.replace(board.body, magnets=tuple(
        dataclasses.replace(m, polarisation_t=tuple(-v for v in m.polarisation_t)) for m in board.body.magnets))
    return {"former_file": (board, "former board file (the AnySkin visualiser's turns)"),
            "right_down_half_turn": (dataclasses.replace(board, chips=half), "right and down chips half a turn"),
            "mirror_image": (dataclasses.replace(board, chips=tuple(mirror)),
                             "mirror image (up and down chips traded, right and down chips half a turn)"),
            "left_handed": (dataclasses.replace(board, chips=left_handed),
                            "left-handed chips at the file's places (the twin's readouts)"),
            "upside_down": (dataclasses.replace(board, chips=upside_down, body=reversed_discs),
                            ("the left-handed chips' axes negated (right-handed: upside down), discs polarised -z: "
                             "the board file"))}


def negated(axis: str) -> str:
    """The signed axis name pointing the other way ("-y" -> "+y")."""
    return ("-" if axis[0] == "+" else "+") + axis[1:]


def square_field_ut(x: np.ndarray, chips_mm: np.ndarray, size_mm: np.ndarray) -> np.ndarray:
    """(C, 3) pad-axes field (uT) of four equal z-polarised discs on a square: ``x`` = centre x, y (mm), turn
    (rad), depth z (mm), side (mm), polarisation (T)."""
    cx, cy, turn, z, side, j = x
    c, s = np.cos(turn), np.sin(turn)
    corners = np.array([[-1, 1], [1, 1], [-1, -1], [1, -1]]) * side / 2 @ np.array([[c, -s], [s, c]]).T + [cx, cy]
    centres = np.c_[corners, np.full(4, z)]
    magnets = Magnets(centres_mm=centres, polarisation_t=np.full(4, j), size_mm=size_mm)
    return discs_field_pad_ut(chips_mm, magnets, centres[None])[0]


def rest_fit(board: Board, rest_ut: np.ndarray) -> dict[str, Any]:
    """The rigid square of discs that best gives ``rest_ut`` (C, 3, chip axes) through ``board``'s chip axes, the
    discs polarised along +z or -z as the board's are (the square's strength is a size, not a sign)."""
    chips_mm, readout = board.chip_positions_mm(), np.transpose(board.chip_matrices(), (0, 2, 1))
    discs = board_magnets(board)
    size, polarity = discs.size_mm, float(np.sign(discs.polarisation_t.sum()))
    lo, hi = [-15.0, -15.0, -np.pi, -20.0, 8.0, 0.2], [15.0, 15.0, np.pi, -1.7, 35.0, 1.5]

    def residual(x: np.ndarray) -> np.ndarray:
        return (np.einsum("cij,cj->ci", readout, polarity * square_field_ut(x, chips_mm, size)) - rest_ut).ravel()

    best = min((least_squares(residual, [dx, dy, turn, -6.5, 20.0, 1.4], bounds=(lo, hi))
                for turn in (0.0, 0.4, 0.8) for dx in (-3.0, 0.0, 3.0) for dy in (-3.0, 0.0, 3.0)),
               key=lambda sol: sol.cost)
    miss = residual(best.x).reshape(-1, 3)
    return {"rms_ut": round(float(np.sqrt(np.mean(miss ** 2))), 1),
            "in_plane_rms_ut": round(float(np.sqrt(np.mean(miss[:, :2] ** 2))), 1),
            "z_rms_ut": round(float(np.sqrt(np.mean(miss[:, 2] ** 2))), 1),
            "square": dict(zip(("centre_x_mm", "centre_y_mm", "turn_rad", "depth_mm", "side_mm", "polarisation_t"),
                               [round(float(v), 3) for v in best.x * [1, 1, 1, 1, 1, polarity]]))}


def press_fit(board: Board, fit: twin_fit.PressLog, test: twin_fit.PressLog, evaluations: int) -> dict[str, Any]:
    """Explained variance of ``board``'s chip axes (one gain per chip) with free discs, rig frame and kernel."""
    start = time.monotonic()
    fitter = twin_fit._Fitter(board, fit, None)
    p0 = twin_fit.initial_params(board, fit)
    free = twin_fit._free("magnets", p0.names)
    subset = np.arange(0, len(fit.readings_ut), 2)
    starts = []
    for mirror in (0.0, 1.0):
        for turn in (0.0, 90.0, 180.0, 270.0):
            q = dataclasses.replace(p0, values=p0.values.copy())
            q.values[q.names.index("turn_deg")], q.values[q.names.index("mirror")] = turn, mirror
            starts.append((fitter.run(q, "file", free, evaluations // 3, rows=subset), q))
    p = min(starts, key=lambda item: item[0])[1]
    fitter.run(p, "file", free, evaluations)
    on_fit = fitter.describe("file", p, 0.0)["ev"]
    gains = twin_fit.solve_readout("file", twin_fit.change_pad_ut(p, fitter.chips_mm, fitter.size, fit),
                                   fit.readings_ut, fitter.axes)
    predicted = np.einsum("cij,ncj->nci", gains, twin_fit.change_pad_ut(p, fitter.chips_mm, fitter.size, test))
    on_test, _ = twin_fit.explained_variance(test.readings_ut, predicted)
    return {"ev_fit_rows": round(float(on_fit), 3), "ev_test_tail": round(float(on_test), 3),
            "rig_mirrored": bool(p.get("mirror") > 0.5), "rig_turn_deg": round(p.get("turn_deg"), 1),
            "seconds": round(time.monotonic() - start, 1)}


def press_logs(board: Board, run: Path, rows: int) -> tuple[twin_fit.PressLog, twin_fit.PressLog]:
    """``rows`` presses spread over the first 80 % of ``run``'s rows, and the last 20 %."""
    log = probe_rows(board, run / "sensor_post_baselines.csv", run / "states.csv",
                     ["time_s", "x_mm", "y_mm", "z_mm"], TRAIN_FRACTION)
    assert log.readings_ut is not None
    ok = np.isfinite(log.stage_xyz_mm).all(axis=1)
    train = np.flatnonzero((log.split == "train") & ok)
    chosen = train[np.unique(np.linspace(0, len(train) - 1, min(rows, len(train))).astype(int))]
    test = np.flatnonzero((log.split == "test") & ok)
    hours = (log.time_s - log.time_s[0]) / 3600.0
    return tuple(twin_fit.PressLog(log.stage_xyz_mm[i], log.readings_ut[i], hours[i])  # type: ignore[return-value]
                 for i in (chosen, test))


def markdown(report: dict[str, Any]) -> str:
    lines = ["# eFlesh chip layouts against the development runs", "",
             ("| layout | rest field, spatial (uT rms; in-plane) | rest field, normal | presses: EV fit rows "
              "| EV test tail | rig mirrored |"), "|---|---|---|---|---|---|"]
    for row in report["layouts"].values():
        s, n, p = row["rest"][SPATIAL], row["rest"][NORMAL], row["presses"]
        lines.append(f"| {row['description']} | {s['rms_ut']:.0f}; {s['in_plane_rms_ut']:.0f} | {n['rms_ut']:.0f}; "
                     f"{n['in_plane_rms_ut']:.0f} | {p['ev_fit_rows']:.3f} | {p['ev_test_tail']:.3f} | "
                     f"{'yes' if p['rig_mirrored'] else 'no'} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of the two eFlesh runs")
    parser.add_argument("--rows", type=int, default=400, help="presses of the spatial run's first 80 %% fitted")
    parser.add_argument("--evaluations", type=int, default=40, help="least-squares evaluations per press fit")
    parser.add_argument("--out", default="docs/results/eflesh/twin/chip_layout.json")
    args = parser.parse_args(argv)
    if not all((args.data / run / "sensor.csv").is_file() for run in (SPATIAL, NORMAL)):
        parser.error(f"{args.data} lacks {SPATIAL} or {NORMAL}: pass --data or set TACTILE_MANIP_EFLESH_DIR")

    board = load_board("eflesh")
    rests = {run: rest_field(board, args.data / run / "sensor.csv", args.data / run / "sensor_post_baselines.csv",
                             TRAIN_FRACTION)[0] for run in (SPATIAL, NORMAL)}
    fit, test = press_logs(board, args.data / SPATIAL, args.rows)
    report: dict[str, Any] = {"board": "eflesh", "train_fraction": TRAIN_FRACTION, "rows": len(fit.readings_ut),
                              "test_rows": len(test.readings_ut), "layouts": {}}
    for name, (candidate, description) in layouts(board).items():
        report["layouts"][name] = {"description": description,
            "rotation_deg_or_axes": [c.axes if c.axes is not None else c.rotation_deg for c in candidate.chips],
            "position_mm": [list(c.position_mm) for c in candidate.chips],
            "discs_polarisation_z_t": [float(j) for j in board_magnets(candidate).polarisation_t],
            "rest": {run: rest_fit(candidate, rest) for run, rest in rests.items()},
            "presses": press_fit(candidate, fit, test, args.evaluations)}
        print(f"{name}: {report['layouts'][name]['presses']['seconds']:.0f} s", flush=True)
    report["machine"] = machine_info()
    publish(report, Path(args.out), markdown)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
