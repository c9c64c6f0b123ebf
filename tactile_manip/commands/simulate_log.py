"""``tactile-manip simulate-log``: a fitted board's simulated reading at every row of a probe log, and its score.

    tactile-manip simulate-log --board my-cube.toml --labels states.csv --label-columns time_s,x_mm,y_mm,z_mm \\
        --readings sensor_post_baselines.csv --out sim.csv

For each row of the log (with ``--readings``: each sensor row matched with its label row, as ``import`` matches
them, in the same order; without it: each label row) the twin (:class:`~tactile_manip.sim.twin.BoardTwin`) gives
the reading at the row's logged probe pose. ``--stream subtracted`` (the default) simulates the baseline-subtracted
reading, ``raw`` the raw one (rest field and chip offsets added); ``--readings`` must then be that stream.

Writes ``--out``: a ``.csv`` laid out as the sensor log (time s, then x, y, z of each chip in its own axes, uT,
firmware order), which ``import --readings-csv`` reads as it reads the real log; or a ``.npz`` holding
``readings`` (N, rows, cols, 3) float32 in pad axes as ``import`` gives them, ``time_s`` and ``stage_xyz_mm``.
With ``--readings`` it prints the explained variance (EV, ``1 - SSE / SS`` about each channel's mean; overall: both
pooled) on the rows after ``--train-fraction`` (the test tail) and on all rows, per channel and overall, writes it
as JSON beside ``--out`` and plots predicted against measured over time, one panel per chip (``--plot``).

    tactile-manip simulate-log --board my-cube.toml --grid --out twin.npz

``--grid`` simulates no log but the twin pressed all over its pad (:func:`~tactile_manip.sim.twin.stage_grid`:
0.5 mm steps over the layer and 4 mm beyond it, 12 approaches up to 6 mm, through the board's rig frame) and
writes them as a dataset of presses whose targets are the stage poses (``x_mm``, ``y_mm``, ``z_mm``): the twin's
presses that ``train --prior`` reads (docs/your_board.md, "Contact from the twin").
"""

from __future__ import annotations

import argparse

from tactile_manip.commands.twin_logs import add_log_arguments


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--board", required=True, metavar="FILE", help="a fitted board file (fit-board's output)")
    add_log_arguments(p)
    p.add_argument("--readings", metavar="CSV",
                   help="the log's sensor stream: rows are matched as import matches them, and scored")
    p.add_argument("--stream", choices=("subtracted", "raw"), default="subtracted",
                   help="simulate the baseline-subtracted reading (default) or the raw one")
    p.add_argument("--out", required=True, metavar="CSV|NPZ", help="simulated readings (.csv or .npz)")
    p.add_argument("--plot", metavar="PNG", help="predicted against measured over time (default: --out's name .png, "
                                                 "with --readings)")
    p.add_argument("--grid", action="store_true",
                   help="no log: the twin pressed all over its pad (0.5 mm steps, 12 approaches to 6 mm), written as "
                        "a dataset (.npz) of presses whose targets are the stage poses, for train --prior")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")


def run(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    import numpy as np

    from tactile_manip.boards import load_board
    from tactile_manip.commands.twin_logs import probe_rows
    from tactile_manip.errors import ConfigError
    from tactile_manip.outputs import check_output_file
    from tactile_manip.sim.twin import BoardTwin
    from tactile_manip.sim.twin_fit import explained_variance

    out = Path(args.out)
    if args.grid:
        return _grid(args, out)
    if out.suffix not in (".csv", ".npz"):
        raise ConfigError(f"--out {out}: write .csv (the sensor log's layout) or .npz (import's readings)")
    if args.labels is None:
        raise ConfigError("--labels is required: the log's probe poses (time_s, x_mm, y_mm, z_mm)")
    plot = Path(args.plot) if args.plot else out.with_suffix(".png") if args.readings else None
    score = out.with_name(out.stem + ".score.json") if args.readings else None
    for path in (out, plot, score):
        if path is not None:
            check_output_file(path, force=args.force)
    board = load_board(args.board)
    twin = BoardTwin(board)
    columns = None if args.label_columns is None else [c.strip() for c in args.label_columns.split(",") if c.strip()]
    rows = probe_rows(board, args.readings, args.labels, columns, args.train_fraction)
    time_h = (rows.time_s - rows.time_s[0]) / 3600.0
    sim = twin.readings_ut(rows.stage_xyz_mm, time_h, raw=args.stream == "raw")  # (N, C, 3) chip axes
    report = None
    if rows.readings_ut is not None:
        tail = rows.split == "test"
        report = {"board": board.name, "stream": args.stream, "rows": int(len(sim)), "test_rows": int(tail.sum()),
                  "train_fraction": args.train_fraction, "channels": _channel_names(board.n_chips)}
        for part, mask in (("test", tail), ("all", np.ones(len(sim), bool))):
            if mask.sum() >= 2:
                ev, per = explained_variance(rows.readings_ut[mask], sim[mask])
                report[f"ev_{part}"] = round(ev, 4)
                report[f"ev_{part}_per_channel"] = [round(v, 4) for v in per]
    _write(out, rows, sim, board)
    written = [str(out)]
    if report is not None:
        assert score is not None and plot is not None
        score.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
        _plot(plot, rows, sim, report, board.name)
        written += [str(score), str(plot)]
        for part, what in (("test", f"the test tail ({report['test_rows']} rows after the first "
                                    f"{args.train_fraction:g})"), ("all", f"all {report['rows']} rows")):
            if f"ev_{part}" in report:
                per = " ".join(f"{n} {v:.2f}" for n, v in zip(report["channels"], report[f"ev_{part}_per_channel"]))
                print(f"EV of the {args.stream} readings on {what}: {report[f'ev_{part}']:.3f} ({per})")
    print(f"wrote {', '.join(written)}: {len(sim)} simulated readings of board {board.name}")
    return 0


def _grid(args: argparse.Namespace, out) -> int:
    """``--grid``: the twin's presses over its pad, as a dataset ``train --prior`` reads."""
    import numpy as np

    from tactile_manip.boards import load_board
    from tactile_manip.data import from_arrays, save_dataset
    from tactile_manip.errors import ConfigError
    from tactile_manip.outputs import check_output_file
    from tactile_manip.sim.twin import BoardTwin, stage_grid

    given = [flag for flag, value in (("--labels", args.labels), ("--readings", args.readings),
                                      ("--plot", args.plot)) if value]
    if given:
        raise ConfigError(f"--grid simulates presses all over the pad, not a log: drop {', '.join(given)}")
    if out.suffix != ".npz":
        raise ConfigError(f"--out {out}: --grid writes a dataset of presses (.npz), which train --prior reads")
    check_output_file(out, force=args.force)
    board = load_board(args.board)
    twin = BoardTwin(board)
    poses = stage_grid(board)
    readings = board.readings_from_chips(twin.readings_ut(poses))
    save_dataset(out, from_arrays(readings, targets=dict(zip(("x_mm", "y_mm", "z_mm"), poses.T)), val_fraction=0.0,
                                  test_fraction=0.0, provenance={"source": f"tactile-manip simulate-log --grid of "
                                                                           f"{board.name}", "layout": board.name,
                                                                 "board": board.record}))
    approaches = len(np.unique(poses[:, 2]))
    print(f"wrote {out}: {len(poses)} presses of board {board.name}'s twin over its pad ({approaches} approaches at "
          f"each of {len(poses) // approaches} places), targets x_mm, y_mm, z_mm (the stage poses)")
    return 0


def _channel_names(n_chips: int) -> list[str]:
    return [f"chip{c + 1}_{a}" for c in range(n_chips) for a in "xyz"]


def _write(out, rows, sim, board) -> None:
    import numpy as np

    if out.suffix == ".csv":
        table = np.column_stack([rows.time_s, sim.reshape(len(sim), -1)])
        np.savetxt(out, table, delimiter=",", fmt="%.6f")
    else:
        np.savez(out, readings=board.readings_from_chips(sim), time_s=rows.time_s,
                 stage_xyz_mm=rows.stage_xyz_mm, split=rows.split.astype(str))


def _plot(path, rows, sim, report, name: str) -> None:
    import numpy as np

    from tactile_manip.plots import _pyplot

    plt = _pyplot()
    n_chips = sim.shape[1]
    fig, axes = plt.subplots(n_chips, 1, figsize=(11, 2.0 * n_chips), sharex=True)
    axes = np.atleast_1d(axes)
    hours = (rows.time_s - rows.time_s[0]) / 3600.0
    tail_start = hours[np.argmax(rows.split == "test")] if (rows.split == "test").any() else None
    for c, ax in enumerate(axes):
        for a, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
            ax.plot(hours, rows.readings_ut[:, c, a], ".", ms=1.5, color=colour, alpha=0.5,
                    label=f"{'xyz'[a]} measured")
            ax.plot(hours, sim[:, c, a], "-", lw=0.6, color=colour, alpha=0.9, label=f"{'xyz'[a]} twin")
        if tail_start is not None:
            ax.axvline(tail_start, color="k", lw=0.8, ls="--")
        ax.set_ylabel(f"chip {c + 1} (uT)")
    axes[0].legend(ncol=6, fontsize=7, loc="upper right")
    axes[-1].set_xlabel("time since the log's first row (h); dashed: start of the test tail")
    test = f", test tail {report['ev_test']:.3f}" if "ev_test" in report else ""
    fig.suptitle(f"twin of {name} against the log ({report['stream']} readings): EV all rows {report['ev_all']:.3f}"
                 f"{test}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
