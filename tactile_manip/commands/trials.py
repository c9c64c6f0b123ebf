"""``tactile-manip trials``: run a reorientation trial scene (every presentation once per method) and report.

Writes ``OUT/trials.jsonl`` (one fsynced line per trial, so a killed run loses no completed trial; continue it
with ``--resume``) and each trial's per-frame streams to ``OUT/frames/`` (``tactile-manip export OUT`` turns
them into a LeRobot dataset; ``--no-frames`` skips them), then the summary (success rates with Wilson 95 %
intervals, angle errors, the paired comparison) and plots. ``tactile-manip score OUT --tolerance-deg X`` re-scores it later.
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", required=True, help="scene TOML, e.g. configs/scenes/reorient_sim.toml")
    p.add_argument("--out", default=None,
                   help="run folder (default: a new runs/trials/<scene name>-<UTC time>; an existing folder needs --resume)")
    p.add_argument("--trials", type=int, default=None, help="override the scene's number of presentations")
    p.add_argument("--methods", default=None, help="comma-separated subset of the scene's methods")
    p.add_argument("--resume", action="store_true", help="continue a killed run in --out (same scene)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--no-frames", dest="frames", action="store_false",
                   help="do not record each trial's per-frame streams to OUT/frames/ (what `export` turns into "
                        "episodes; about 0.5 kB per frame)")


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from tactile_manip.outputs import check_output_dir
    from tactile_manip.trials.log import run_folder
    from tactile_manip.trials.runner import run_trials
    from tactile_manip.trials.scene import load_scene

    scene = load_scene(args.config)
    if args.trials is not None:
        scene = dataclasses.replace(scene, trials=args.trials)
    if args.methods:
        wanted = [m.strip() for m in args.methods.split(",") if m.strip()]
        known = {m.name: m for m in scene.methods}
        unknown = [m for m in wanted if m not in known]
        if unknown:
            raise ValueError(f"--methods: {unknown} not in the scene's methods {sorted(known)}")
        scene = dataclasses.replace(scene, methods=[known[m] for m in wanted])
    out = check_output_dir(run_folder(scene.name, args.out, resume=args.resume))
    summary = run_trials(scene, out, scene_path=args.config, resume=args.resume, progress=not args.quiet,
                         frames=args.frames)
    md = out / "summary.md"
    if md.exists():
        print(md.read_text(), end="")
    print(f"wrote {out}/trials.jsonl, summary.md, summary.json and plots")
    return 0 if summary is not None else 1
