"""``tactile-manip fit-board``: fit a board file's twin to what its owner recorded, and write the fitted board file.

    tactile-manip fit-board --board eflesh --raw sensor.csv --subtracted sensor_post_baselines.csv \\
        --labels states.csv --label-columns time_s,x_mm,y_mm,z_mm --out my-cube.toml
    tactile-manip fit-board --board eflesh --raw untouched.csv --presses presses.csv --labels states.csv \\
        --labelled 25 --out my-cube.toml
    tactile-manip fit-board --board eflesh --raw sensor.csv --subtracted sensor_post_baselines.csv --out my-cube.toml

The untouched board's raw field comes from ``--raw``: an untouched capture (tens of seconds before any press), or,
as in logs whose every raw row is a press, the raw stream with ``--subtracted``, the logger's baseline-subtracted
copy (their difference is the logger's baseline). The presses are the baseline-subtracted stream (``--subtracted``)
or ``--presses`` (raw rows, less the untouched field), matched by time with the label log as ``import`` matches
them; the fit sees only the first ``--train-fraction`` of the rows (and of those, ``--labelled K`` drawn at random).
What is fitted, in stages: :mod:`tactile_manip.sim.twin_fit`. The output is the board file with the fitted magnets,
a ``[twin]`` table and a ``[fit]`` table saying what was fitted on what, with the EV and rest-field residual of each
stage; ``load_board`` reads it and ``simulate-log`` simulates it.

Without ``--labels`` no probe pose is read at all: the twin is fitted to the rest field and the readings of the
fitting rows' presses alone (:mod:`tactile_manip.sim.twin_blind`: the discs from the rest field, the press kernel
and the chips' readouts from the readings), in the pad frame of the board file, for contact with zero labels.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from tactile_manip.commands.twin_logs import add_log_arguments

if TYPE_CHECKING:
    import numpy as np

    from tactile_manip.boards.load import Board

DEFAULT_ROWS = 800  # presses fitted at most (evenly drawn from the fitting rows): a fit in about two minutes
PRESS_NOISE_MULTIPLE = 3.0  # without labels, a row is a press where its field norm exceeds this many times the
                            # chips' noise over all channels (a row of noise has no direction to place)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--board", required=True, metavar="NAME|FILE", help="the board file to fit (e.g. eflesh)")
    p.add_argument("--raw", required=True, metavar="CSV",
                   help="raw sensor stream (time, then x, y, z per chip, uT): untouched, or with --subtracted")
    p.add_argument("--subtracted", metavar="CSV",
                   help="the logger's baseline-subtracted copy of --raw, row for row (the presses)")
    p.add_argument("--presses", metavar="CSV", help="raw sensor stream of the presses (without --subtracted)")
    add_log_arguments(p)
    p.add_argument("--labelled", default="all", metavar="K|all",
                   help="fit on K labelled presses drawn at random (with --seed) from the fitting rows (default all)")
    p.add_argument("--rows", type=int, default=DEFAULT_ROWS, help=f"presses fitted at most (default {DEFAULT_ROWS})")
    p.add_argument("--evaluations", type=int, default=60, help="least-squares evaluations per stage (default 60)")
    p.add_argument("--search-chip-order", action="store_true",
                   help="search the chips' order too: every placement of them on their positions, up to the pad's "
                        "turns and mirror images (15 for the five-chip cross; minutes more)")
    p.add_argument("--seed", type=int, default=0, help="seed of --labelled's draw")
    p.add_argument("--name", help="the fitted board's name (default: the board's name + '-fitted')")
    p.add_argument("--out", required=True, metavar="TOML", help="the fitted board file to write")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.add_argument("--quiet", action="store_true", help="print only the result")


def run(args: argparse.Namespace) -> int:
    import dataclasses
    import sys
    import time

    import numpy as np

    from tactile_manip.boards import load_board
    from tactile_manip.commands.twin_logs import (
        file_hash,
        probe_rows,
        read_chip_stream,
        rest_field,
    )
    from tactile_manip.errors import ConfigError
    from tactile_manip.outputs import check_output_file
    from tactile_manip.sim.twin_fit import PressLog, fit_twin

    started = time.monotonic()
    say = (lambda line: None) if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    out = check_output_file(args.out, force=args.force)
    if out.suffix != ".toml":
        raise ConfigError(f"--out {out}: a board file ends in .toml")
    board = load_board(args.board)
    board.require_simulation()
    labelled = _labelled(args.labelled)
    if args.labels is None and labelled is not None:
        raise ConfigError(f"--labelled {labelled} draws labelled presses from --labels, which is not given (without "
                          "--labels the fit reads no label at all)")
    if (args.subtracted is None) == (args.presses is None):
        raise ConfigError("give the presses either as --subtracted (the baseline-subtracted copy of --raw) or as "
                          "--presses (raw press rows, with --raw an untouched capture), one of the two")
    if args.rows < 10:
        raise ConfigError(f"--rows must be at least 10, got {args.rows}")
    rest, rest_info = rest_field(board, args.raw, args.subtracted, args.train_fraction)
    say(f"rest field: median of {rest_info['from']}, {rest_info['rows']} rows over {rest_info['seconds']:g} s "
        f"({time.monotonic() - started:.1f} s)")
    if args.subtracted is not None:
        stream = args.subtracted
    else:
        t, chips = read_chip_stream(args.presses, board)
        stream = (t, chips - rest)
    if args.labels is None:
        fitted, provenance, summary = _fit_unlabelled(args, board, stream, rest, rest_info, say)
        _write(out, fitted, board, header=f"{fitted.name}: a twin of board {board.name}, fitted by tactile-manip "
               "fit-board without labels")
        print(f"wrote {out}: board {fitted.name}, {summary} ({time.monotonic() - started:.0f} s)")
        return 0
    rows = probe_rows(board, stream, args.labels, _columns(args.label_columns), args.train_fraction,
                      labelled=labelled, seed=args.seed)
    fit_rows = np.flatnonzero((rows.split == "train") & np.isfinite(rows.stage_xyz_mm).all(axis=1))
    if len(fit_rows) < 10:
        raise ConfigError(f"{len(fit_rows)} labelled presses in the fitting rows: the twin needs at least 10")
    chosen = fit_rows[np.unique(np.linspace(0, len(fit_rows) - 1, min(args.rows, len(fit_rows))).astype(int))]
    assert rows.readings_ut is not None
    time_h = (rows.time_s - rows.time_s[0]) / 3600.0
    log = PressLog(rows.stage_xyz_mm[chosen], rows.readings_ut[chosen], time_h[chosen])
    say(f"presses: {len(chosen)} of the {len(fit_rows)} labelled fitting rows (first {args.train_fraction:g} of "
        f"{len(rows.split)} matched rows)")
    fit = fit_twin(board, log, rest_ut=rest, max_evaluations=args.evaluations, search_order=args.search_chip_order,
                   report=say)
    inputs = {"board": str(args.board), "raw": str(args.raw), "subtracted": args.subtracted, "presses": args.presses,
              "labels": str(args.labels)}
    provenance = {
        "command": "tactile-manip fit-board", "template": board.name, "created_utc": time.strftime(
            "%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "files": {k: str(v) for k, v in inputs.items() if v is not None},
        "sha256_16": {k: file_hash(v) for k, v in inputs.items() if v is not None and k != "board"},
        "label_columns": args.label_columns or "", "train_fraction": args.train_fraction,
        "labelled": "all" if labelled is None else labelled, "seed": args.seed,
        "rows": {"matched": len(rows.split), "fitting": len(fit_rows), "fitted": len(chosen)},
        "rest": rest_info, "stream_scored": "baseline-subtracted",
        "ev_on_fitted_rows": {name: s["ev"] for name, s in fit.stages.items()},
        "rest_rms_ut": {name: s["rest_rms_ut"] for name, s in fit.stages.items() if s["rest_rms_ut"] is not None},
        "ev_per_channel": fit.stages["cells"]["ev_per_channel"],
        "stage_notes": {name: s["note"] for name, s in fit.stages.items() if "note" in s},
        "chip_turns_found": fit.chip_turns, "seconds": round(time.monotonic() - started, 1),
    }
    if fit.orders:  # chip i sits at the file's chip order[i]'s place: EV and rest field of each placement
        provenance["chip_orders"] = {"best": fit.orders[0]["order"], "searched": len(fit.orders),
                                     "ev_by_order": {"-".join(map(str, o["order"])): o["ev"] for o in fit.orders},
                                     "rest_rms_ut_by_order": {"-".join(map(str, o["order"])): o["rest_rms_ut"]
                                                              for o in fit.orders}}
    name = args.name or f"{board.name}-fitted"
    source = (f"fitted by tactile-manip fit-board to {Path(args.raw).name} and {Path(args.labels).name} "
              f"(first {args.train_fraction:g} of the rows) from the board file {board.name}; [fit] says what on what")
    fitted = dataclasses.replace(fit.board, name=name, source=source, fit=provenance, path=None)
    _write(out, fitted, board, header=f"{name}: a twin of board {board.name}, fitted by tactile-manip fit-board")
    stages = ", ".join(f"{k} {v['ev']:.3f}" for k, v in fit.stages.items())
    print(f"wrote {out}: board {name}, EV on the {len(chosen)} fitted presses by stage: {stages} "
          f"({time.monotonic() - started:.0f} s)")
    return 0


def _write(out: Path, fitted: Board, board: Board, *, header: str) -> None:
    """Write ``fitted`` as a board file at ``out``, through a temporary file that must read back as a board."""
    import os
    import tempfile

    from tactile_manip.boards import load_board
    from tactile_manip.boards.write import board_toml

    fd, tmp = tempfile.mkstemp(suffix=".toml", dir=out.parent if str(out.parent) else ".")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(board_toml(fitted, header=header))
        load_board(tmp)  # the file reads back as a board before it takes its name
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _fit_unlabelled(args: argparse.Namespace, board: Board, stream: str | tuple[np.ndarray, np.ndarray],
                    rest: np.ndarray, rest_info: dict, say: Callable[[str], None]) -> tuple[Board, dict, str]:
    """The twin fitted to the rest field and the fitting rows' presses without any label: the fitted board (with
    its ``[fit]`` table), and a summary line."""
    import dataclasses
    import time

    import numpy as np

    from tactile_manip.commands.twin_logs import file_hash, read_chip_stream
    from tactile_manip.sim.twin_blind import MIN_PRESSES, fit_twin_unlabelled
    from tactile_manip.sim.twin_fit import TwinFitError

    started = time.monotonic()
    t, chips = stream if isinstance(stream, tuple) else read_chip_stream(stream, board)
    n_fit = max(1, int(len(t) * args.train_fraction))
    noise = np.sqrt(board.n_chips * (2 * board.chip.noise_xy_ut ** 2 + board.chip.noise_z_ut ** 2))
    pressed = np.flatnonzero(np.linalg.norm(chips[:n_fit].reshape(n_fit, -1), axis=1) > PRESS_NOISE_MULTIPLE * noise)
    if len(pressed) < MIN_PRESSES:
        raise TwinFitError(f"{len(pressed)} presses in the first {args.train_fraction:g} of the {len(t)} rows (a row "
                           f"whose field exceeds {PRESS_NOISE_MULTIPLE * noise:.0f} uT): a fit without labels needs "
                           f"at least {MIN_PRESSES}")
    chosen = pressed[np.unique(np.linspace(0, len(pressed) - 1, min(args.rows, len(pressed))).astype(int))]
    say(f"presses: {len(chosen)} of the {len(pressed)} pressed rows among the first {args.train_fraction:g} of "
        f"{len(t)} rows, no labels")
    fit = fit_twin_unlabelled(board, chips[chosen], rest, report=say)
    inputs = {"board": str(args.board), "raw": str(args.raw), "subtracted": args.subtracted, "presses": args.presses}
    provenance = {
        "command": "tactile-manip fit-board", "template": board.name, "created_utc": time.strftime(
            "%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "files": {k: str(v) for k, v in inputs.items() if v is not None},
        "sha256_16": {k: file_hash(v) for k, v in inputs.items() if v is not None and k != "board"},
        "train_fraction": args.train_fraction, "labelled": 0, "frame": "pad (no rig frame: no labels)",
        "rows": {"stream": len(t), "fitting": int(n_fit), "pressed": len(pressed),
                 "fitted": len(chosen)},
        "rest": rest_info, "stream_scored": "baseline-subtracted",
        "stages": fit.stages, "seconds": round(time.monotonic() - started, 1),
    }
    name = args.name or f"{board.name}-fitted"
    source = (f"fitted by tactile-manip fit-board without labels to {Path(args.raw).name} (first "
              f"{args.train_fraction:g} of the rows) from the board file {board.name}; [fit] says what on what")
    fitted = dataclasses.replace(fit.board, name=name, source=source, fit=provenance, path=None)
    last = fit.stages["readout"]
    return fitted, provenance, (f"no labels: EV {last['ev']:.3f} of the {len(chosen)} fitted presses by their "
                                f"latent places, rest field rms {fit.stages['rest']['rest_rms_ut']:.0f} uT")


def _labelled(text: str) -> int | None:
    from tactile_manip.errors import ConfigError

    if text == "all":
        return None
    if not text.isdigit() or int(text) < 10:
        raise ConfigError(f"--labelled takes a count of at least 10 presses, or all; got {text!r}")
    return int(text)


def _columns(text: str | None) -> list[str] | None:
    return None if text is None else [c.strip() for c in text.split(",") if c.strip()]
