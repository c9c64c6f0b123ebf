"""What ``fit-board`` and ``simulate-log`` read from a probe rig's logs: the untouched board's field, and the
presses with their logged probe poses, matched by time as ``import`` matches them.
"""

from __future__ import annotations

import argparse
import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile_manip.boards.load import Board
from tactile_manip.errors import DatasetError

POSE_COLUMNS = ("x_mm", "y_mm", "z_mm")
MIN_REST_ROWS = 20          # fewer untouched rows cannot tell a steady field from a drifting one
MIN_REST_SECONDS = 1.0
REST_NOISE_MULTIPLE = 10.0  # an untouched row lies within this many chip noise sigmas of the median field
REST_FLOOR_UT = 100.0       # ... or within this, whichever is wider
# a logger's baseline drifts over hours of presses (13-60 uT rms in the eFlesh runs, 140 uT at their 99th
# percentile); only a baseline that moves as much as a hard press (thousands of uT) is no baseline
BASELINE_NOISE_MULTIPLE = 100.0
BASELINE_FLOOR_UT = 1000.0


def add_log_arguments(p: argparse.ArgumentParser) -> None:
    """The label options both commands share."""
    p.add_argument("--labels", metavar="CSV", help="the rig's label log (states.csv): time (s), probe x, y, z "
                   "(mm), ... (fit-board without it fits the readings alone, no label)")
    p.add_argument("--label-columns", metavar="A,B,...",
                   help="names of the label CSV's columns, with units, e.g. time_s,x_mm,y_mm,z_mm,force_gf "
                        "(default: the CSV's header); the probe pose is x_mm, y_mm, z_mm")
    p.add_argument("--train-fraction", type=float, default=0.8,
                   help="the first share of the log's rows in time order that the fit sees (default 0.8, the "
                        "eFlesh protocol); simulate-log scores the rows after it")


def file_hash(path: str | Path) -> str:
    """SHA-256 of a file, first 16 hex."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def read_chip_stream(path: str | Path, board: Board) -> tuple[np.ndarray, np.ndarray]:
    """(M,) times (s) and (M, C, 3) chip-axes values (uT, firmware order) of a sensor CSV or recording.

    Raises:
        DatasetError: the file's chip count or wire format disagrees with the board.
    """
    from tactile_manip.data.streams import read_reading_stream

    t, values, info = read_reading_stream(path)
    if values.ndim == 4:  # a recording holds cells of its own layout
        if info.get("layout") != board.name:
            raise DatasetError(f"{path}: recorded from board {info.get('layout')}, not {board.name}")
        return t, board_chips(board, values)
    if values.ndim != 2 or values.shape[1] != 3 * board.n_chips:
        raise DatasetError(f"{path}: {values.shape[-1] + 1} columns, expected {1 + 3 * board.n_chips}: time (s), then "
                           f"x, y, z of each of the {board.n_chips} chips of board {board.name}")
    if not np.isfinite(values).all():
        raise DatasetError(f"{path}: row {int(np.flatnonzero(~np.isfinite(values).all(1))[0])} holds a value that is "
                           "not a number")
    return t, values.reshape(len(values), board.n_chips, 3)


def board_chips(board: Board, readings: np.ndarray) -> np.ndarray:
    """(M, R, C, 3) pad-axes readings on the board's cells -> (M, n_chips, 3) chip axes, firmware order."""
    cols = board.grid[1]
    index = [r * cols + c for r, c in (chip.cell for chip in board.chips)]
    flat = np.asarray(readings, np.float64).reshape(len(readings), -1, 3)[:, index]
    return np.einsum("nji,mnj->mni", board.chip_matrices(), flat)


def rest_field(board: Board, raw: str | Path, subtracted: str | Path | None, train_fraction: float
               ) -> tuple[np.ndarray, dict]:
    """(C, 3) the untouched board's raw reading (chip axes, uT), and what it was taken from.

    With ``subtracted`` (a logger's baseline-subtracted copy of ``raw``, row for row) the logger's baseline is
    their difference, its median over the first ``train_fraction`` of the rows; else ``raw`` is an untouched
    capture and its median is the field.

    Raises:
        DatasetError: a stream too short, not at rest, or the two streams not row for row the same.
    """
    t, values = read_chip_stream(raw, board)
    if subtracted is not None:
        t2, sub = read_chip_stream(subtracted, board)
        if len(t2) != len(t) or not np.allclose(t2, t, atol=1e-6):
            raise DatasetError(f"{subtracted}: {len(t2)} rows against {len(t)} in {raw}; the baseline-subtracted "
                               "stream must be the raw stream's rows, row for row")
        n = max(1, int(len(t) * train_fraction))
        values, t, what = (values - sub)[:n], t[:n], "the logger's baseline (raw - subtracted)"
        multiple, floor = BASELINE_NOISE_MULTIPLE, BASELINE_FLOOR_UT
    else:
        what, multiple, floor = "an untouched capture", REST_NOISE_MULTIPLE, REST_FLOOR_UT
    if len(t) < MIN_REST_ROWS or t[-1] - t[0] < MIN_REST_SECONDS:
        raise DatasetError(f"{raw}: {len(t)} rows over {t[-1] - t[0] if len(t) else 0:.2g} s is too short to fit: "
                           f"record at least {MIN_REST_ROWS} rows and {MIN_REST_SECONDS:g} s of the untouched board "
                           "(tens of seconds is better)")
    median = np.median(values, axis=0)
    noise = np.array([board.chip.noise_xy_ut, board.chip.noise_xy_ut, board.chip.noise_z_ut])
    limit = np.maximum(multiple * noise, floor)
    spread = np.percentile(np.abs(values - median), 99, axis=0)
    if (spread > limit).any():
        c, a = np.unravel_index(int(np.argmax(spread / limit)), spread.shape)
        raise DatasetError(f"{raw}: {what} is not at rest: chip {c + 1} {'xyz'[a]} moves {spread[c, a]:.0f} uT from "
                           f"its median (more than {limit[a]:.0f} uT); record the board untouched, or give the "
                           "logger's baseline-subtracted stream with --subtracted")
    return median, {"from": what, "rows": int(len(t)), "seconds": round(float(t[-1] - t[0]), 1),
                    "p99_spread_ut": round(float(spread.max()), 1)}


@dataclass(frozen=True)
class ProbeRows:
    """A log's rows as ``import`` gives them: times (s), (N, 3) probe poses (mm), (N, C, 3) chip-axes readings (uT;
    None without a sensor stream), the dataset split of each row and the dataset itself."""

    time_s: np.ndarray
    stage_xyz_mm: np.ndarray
    readings_ut: np.ndarray | None
    split: np.ndarray
    dataset: object | None


def probe_rows(board: Board, readings: str | Path | tuple | None, labels: str | Path, label_columns: list[str] | None,
               train_fraction: float, *, labelled: int | None = None, seed: int = 0) -> ProbeRows:
    """Match a sensor stream (a file, or a (t_s, (M, C, 3) chip values) pair) with its label log as ``import``
    does (:func:`~tactile_manip.data.from_probe_logs`, chronological split); without a sensor stream, the label
    rows themselves.

    Raises:
        DatasetError: a label log without the pose columns, or streams that do not match.
    """
    if not 0.0 < train_fraction <= 1.0:
        raise DatasetError(f"--train-fraction must be in (0, 1], got {train_fraction}")
    if readings is None:
        from tactile_manip.data.streams import label_stream

        cols, _ = label_stream(str(labels), label_columns, "log")
        _check_pose(cols, labels)
        pose = np.column_stack([cols[c] for c in POSE_COLUMNS])
        n_fit = int(round(len(pose) * train_fraction))
        split = np.where(np.arange(len(pose)) < n_fit, "train", "test")
        return ProbeRows(cols["time_s"], pose, None, split, None)
    from tactile_manip.data import from_probe_logs

    if isinstance(readings, tuple):
        t, chips = readings
        readings = (t, chips.reshape(len(chips), -1))
    data = from_probe_logs([readings], [str(labels)], targets=list(POSE_COLUMNS), label_columns=label_columns,
                           layout=board, test_fraction=round(1.0 - train_fraction, 9), labelled=labelled, seed=seed)
    pose = np.column_stack([data.target(c) for c in POSE_COLUMNS]).astype(np.float64)
    return ProbeRows(np.asarray(data.extras["time_s"], np.float64), pose, board_chips(board, data.readings),
                     np.asarray(data.split), data)


def _check_pose(cols: dict, labels: str | Path) -> None:
    missing = [c for c in POSE_COLUMNS if c not in cols]
    if missing:
        raise DatasetError(f"{labels}: no {', '.join(missing)} column among {','.join(cols)}: the twin needs the probe's "
                           "x_mm, y_mm, z_mm (name the columns with --label-columns)")
