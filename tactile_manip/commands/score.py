"""``tactile-manip score``: re-score a saved trial run at another tolerance, without re-running it.

Reads ``RUN_DIR/trials.jsonl`` (and ``run.json`` when present), writes ``summary_<tol>deg.json``,
``summary_<tol>deg.md``, ``errors_<tol>deg.png`` and ``success_vs_tolerance_<tol>deg.png`` to ``--out``
(default: the run directory) and prints the markdown summary.
"""

from __future__ import annotations

import argparse
import math

MAX_TOLERANCE_DEG = 90.0  # axial errors lie in (-90, 90] deg: a wider tolerance accepts every executed trial


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_dir", metavar="RUN_DIR", help="a run directory (holds trials.jsonl)")
    p.add_argument("--tolerance-deg", type=float, default=5.0,
                   help="success tolerance on |final - target|, deg (default 5)")
    p.add_argument("--out", default=None, metavar="DIR", help="folder for the report files (default: RUN_DIR)")
    p.add_argument("--title", default=None,
                   help="heading of the summary and figures (default: the title of the run's task)")
    p.add_argument("--force", action="store_true", help="replace the report of an earlier scoring at this tolerance")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from tactile_manip.outputs import check_command_folder, check_report_folder, claim_folder
    from tactile_manip.errors import ConfigError
    from tactile_manip.trials.log import TrialLogError, read_run_info, read_trials, trials_path
    from tactile_manip.trials.report import tolerance_tag, write_report

    tol_deg = args.tolerance_deg
    if not (math.isfinite(tol_deg) and 0.0 < tol_deg <= MAX_TOLERANCE_DEG):
        raise ConfigError(f"--tolerance-deg must be in (0, {MAX_TOLERANCE_DEG:g}] deg, got {tol_deg}")
    run_dir = Path(args.run_dir)
    if not run_dir.is_dir():
        raise TrialLogError(f"no run directory at {run_dir}")
    tolerance_rad = math.radians(tol_deg)
    tag = tolerance_tag(tolerance_rad)
    files = [f"summary{tag}.md", f"summary{tag}.json", f"errors{tag}.png", f"success_vs_tolerance{tag}.png"]
    in_run = args.out is None or Path(args.out).resolve() == run_dir.resolve()
    if in_run and read_run_info(run_dir) is not None:  # the run's own folder (its run.json: trials wrote it)
        out = check_report_folder(run_dir, files, force=args.force)
    else:
        out = check_command_folder(args.out or run_dir, "score", files, force=args.force, also=("trials",))
    file = trials_path(run_dir)
    records = read_trials(file)
    if not records:
        raise TrialLogError(f"{file} holds no trial records yet: nothing to score")
    try:
        if not in_run:
            claim_folder(out, "score")
        write_report(out, records, tolerance_rad, title=args.title, tag=tag, run_info=read_run_info(run_dir))
    except ValueError as e:  # duplicated trials or unpaired seeds: the log is not a consistent run
        raise TrialLogError(f"{file}: {e}") from e
    print((out / f"summary{tag}.md").read_text(encoding="utf-8"), end="")
    print(f"wrote {out}/summary{tag}.md, summary{tag}.json, errors{tag}.png, success_vs_tolerance{tag}.png")
    return 0
