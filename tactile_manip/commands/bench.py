"""``tactile-manip bench``: speed against error of every method on this machine, in one report.

Runs the baselines and the default model (one pass and symmetry-averaged), with ``--candidates FILE`` the models
a candidates file names (a repository's reference models, a study's training runs, your own) and with ``--model``
single files, on onnxruntime with 1 thread and all threads, on a dynamically int8-quantised copy, and in torch
eager from the checkpoint, through the same readings. Writes ``OUT/report.md``, ``report.json`` and
``pareto.png`` and prints the table. Missing model files are skipped with a note.
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, help="folder for report.md, report.json and pareto.png")
    p.add_argument("--force", action="store_true", help="replace the report of an earlier run in --out")
    p.add_argument("--quick", action="store_true",
                   help="3 readings per test object, 6 trials, 1 s per timing (about 4 minutes on 2 cores)")
    p.add_argument("--model", action="append", default=[], metavar="NAME=PATH",
                   help="also measure this exported model (repeatable); its checkpoint is best.pt beside it")
    p.add_argument("--methods", default=None,
                   help="comma-separated subset of methods (default: all found): the baselines bilinear and "
                        "bicubic, the default model supermag and supermag_sym (averaged over the sensor's 8 "
                        "symmetries), the models of --candidates (with _sym where symmetrized) and of --model; e.g. "
                        "'bilinear,supermag'")
    p.add_argument("--runtimes", default=None,
                   help="comma-separated subset of ort-1,ort-all,ort-int8,torch for the models (default: all)")
    p.add_argument("--data", default="data/supermag.npz",
                   help="dataset whose test split is scored (missing: simulate the config's test objects)")
    p.add_argument("--dataset-config", default="configs/dataset/supermag.toml",
                   help="dataset config whose test objects are simulated when --data is missing")
    p.add_argument("--scene", default=None,
                   help="trial scene TOML (default: the six rods of configs/scenes/reorient_sim.toml, built in)")
    p.add_argument("--trials", type=int, default=None, help="presentations per method (default 30; quick 6; 0: none)")
    p.add_argument("--per-object", type=int, default=None,
                   help="readings per test object (default: all of the test split; quick 3)")
    p.add_argument("--root", default=".", help="repository root the default model paths are under (default: .)")
    p.add_argument("--candidates", action="append", default=[], metavar="FILE",
                   help="also the models this TOML names (repeatable, read in order: a file's [checkpoints] may name "
                        "the models of an earlier one; paths under --root): [[model]] tables (name, path, optional "
                        "checkpoint, symmetrized, runtimes, untrained), [[runs]] tables of training configs, "
                        "[checkpoints] NAME = \"RUN/best.pt\"")


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from tactile_manip.bench.candidates import RUNTIMES, candidates_file, default_models, parse_model_spec
    from tactile_manip.bench.report import markdown_table, pose_table, write_report
    from tactile_manip.bench.suite import BenchSettings, run_bench
    from tactile_manip.outputs import check_command_folder, claim_folder

    check_command_folder(args.out, "bench", ("report.md", "report.json", "pareto.png"), force=args.force)
    settings = BenchSettings.quick_settings() if args.quick else BenchSettings()
    if args.trials is not None:
        settings = dataclasses.replace(settings, trials=args.trials)
    if args.per_object is not None:
        settings = dataclasses.replace(settings, per_object=args.per_object)
    models = default_models(args.root)
    for path in args.candidates:
        models = candidates_file(path, args.root, models)
    models += [parse_model_spec(s) for s in args.model]
    taken = [e.name for e in models]
    repeated = sorted({n for n in taken if taken.count(n) > 1})
    if repeated:
        raise ValueError(f"the bench's models are named more than once: {', '.join(repeated)} (--candidates and "
                         "--model each add models; name each once)")
    runtimes = _split(args.runtimes) or list(RUNTIMES)
    report = run_bench(settings=settings, models=models, runtimes=runtimes, data_path=args.data,
                       dataset_config=args.dataset_config, scene_path=args.scene, methods=_split(args.methods),
                       log=lambda line: print(line, file=sys.stderr, flush=True))
    paths = write_report(claim_folder(args.out, "bench"), report)
    print(markdown_table(report["rows"]), end="")
    print("\nReading -> angle, one and two pads:\n" + pose_table(report["rows"]), end="")
    for note in report["notes"]:
        print(f"note: {note}")
    print(f"took {report['seconds']:.0f} s; wrote {', '.join(str(p) for p in paths)}")
    return 0


def _split(text: str | None) -> list[str] | None:
    return [t.strip() for t in text.split(",") if t.strip()] if text else None
