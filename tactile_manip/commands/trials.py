"""``tactile-manip trials``: run a trial scene (every presentation once per method, its task each time) and report.

Writes ``OUT/trials.jsonl`` (one fsynced line per trial, so a killed run loses no completed trial; continue it
with ``--resume``) and each trial's per-frame streams to ``OUT/frames/`` (``tactile-manip export OUT`` turns
them into a LeRobot dataset; ``--no-frames`` skips them), then the summary (success rates with Wilson 95 %
intervals, angle errors, the paired comparison) and plots. ``tactile-manip score OUT --tolerance-deg X`` re-scores
it later. ``--rerun`` lets you watch the run in Rerun (every sensor frame, the arm, each estimate and outcome): in
a viewer, a .rrd file or a gRPC server on this machine, which stops when the run ends (done, failed, Ctrl-C or
SIGTERM).
"""

from __future__ import annotations

import argparse

from tactile_manip.commands.rerun_options import add_rerun_options, check_rerun_options


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", required=True, help="scene TOML, e.g. configs/scenes/reorient_sim.toml")
    p.add_argument("--out", default=None,
                   help="run folder (default: a new runs/trials/<scene name>-<UTC time>; an existing folder needs --resume)")
    p.add_argument("--trials", type=int, default=None, help="override the scene's number of presentations")
    p.add_argument("--methods", default=None, help="comma-separated subset of the scene's methods")
    p.add_argument("--resume", action="store_true", help="continue a killed run in --out (same scene)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--force", action="store_true", help="with --rerun --save: overwrite an existing .rrd file")
    add_rerun_options(p, what="the run (every sensor frame, the arm, each estimate and outcome)")
    p.add_argument("--no-frames", dest="frames", action="store_false",
                   help="do not record each trial's per-frame streams to OUT/frames/ (what `export` turns into "
                        "episodes; about 0.5 kB per frame)")
    p.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                   help="run the trials as Ray tasks: 'local' (the default without ADDRESS: a private instance on "
                        "this machine with --workers CPUs), 'auto' or HOST:PORT; the same log as a local run, in "
                        "trial order (extra 'ray')")
    p.add_argument("--workers", type=int, default=0, help="with --ray local: CPUs of the private instance (0 = all)")
    p.add_argument("--block-trials", type=int, default=None,
                   help="presentations per Ray task, every method of each (default 4); only with --ray")


def run(args: argparse.Namespace) -> int:
    import dataclasses
    from pathlib import Path

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
    check_rerun_options(args)
    _check_ray_options(args)
    out = check_output_dir(run_folder(scene.name, args.out, resume=args.resume))
    executor = _ray_executor(args) if args.ray is not None else None
    observer = _rerun_observer(args, scene.name) if args.rerun else None
    try:
        summary = run_trials(scene, out, scene_path=args.config, resume=args.resume, progress=not args.quiet,
                             trial_observer=observer, frames=args.frames, executor=executor)
    except BaseException:  # an error, Ctrl-C or SIGTERM: the viewer's server stops too
        if observer is not None:
            observer.close()
            if args.save and observer.trials == 0:  # refused before any trial ran: leave no recording behind
                Path(args.save).unlink(missing_ok=True)
        raise
    if observer is not None:
        observer.close()
    return _report(out, summary)


def _report(out, summary) -> int:
    md = out / "summary.md"
    if md.exists():
        print(md.read_text(), end="")
    print(f"wrote {out}/trials.jsonl, summary.md, summary.json and plots")
    return 0 if summary is not None else 1


def _check_ray_options(args: argparse.Namespace) -> None:
    if args.ray is None:
        if args.block_trials is not None or args.workers:
            raise ValueError("--block-trials and --workers apply to --ray runs only")
        return
    from tactile_manip.cluster.connect import check_address, preflight

    if args.rerun:
        raise ValueError("--rerun watches trials in this process; it cannot watch Ray workers (drop --ray, or "
                         "export the run afterwards: tactile-manip export RUN --format rrd)")
    if args.workers < 0:
        raise ValueError(f"--workers must be >= 0, got {args.workers}")
    if args.block_trials is not None and args.block_trials < 1:
        raise ValueError(f"--block-trials must be >= 1, got {args.block_trials}")
    address = check_address(args.ray)
    if address is not None and args.workers:
        raise ValueError("--workers sets the CPUs of a private local Ray instance; a cluster uses all of its own")
    preflight(address)  # an unreachable cluster fails here, before the run folder


def _ray_executor(args: argparse.Namespace):
    from tactile_manip.cluster.connect import check_address
    from tactile_manip.cluster.trials import DEFAULT_BLOCK_TRIALS, RayExecutor

    return RayExecutor(check_address(args.ray), num_cpus=args.workers or None,
                       block_trials=args.block_trials or DEFAULT_BLOCK_TRIALS)


def _rerun_observer(args: argparse.Namespace, name: str):
    import sys

    from tactile_manip.interop.rerun_log import EntityPaths, blueprint
    from tactile_manip.interop.rerun_sink import open_live
    from tactile_manip.interop.rerun_trials import RerunTrialObserver

    sink = open_live(save=args.save, spawn=args.spawn or (args.save is None and not args.serve), serve=args.serve,
                     bind=args.bind, port=args.rerun_port, recording_name=f"trials {name}",
                     default_blueprint=blueprint(EntityPaths("mbts"), robot=True, depth=False))
    try:
        print(f"trials: Rerun, {sink.description}" + "".join(f"\ntrials: {n}" for n in sink.notes), file=sys.stderr)
        return RerunTrialObserver(sink)
    except BaseException:
        sink.close()
        raise
