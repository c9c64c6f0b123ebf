"""Wall time of a board owner's few-label calibration, stage by stage, against the 10-minute goal.

    python -m benchmarks.calibrate_time --runs ../shared/data/eflesh_dev                        # both runs, K = 25
    python -m benchmarks.calibrate_time --runs ../shared/data/eflesh_dev --run spatial_20250316_155729 --seeds 0 1

A calibration is a route: a list of ``tactile-manip`` commands, each run as a subprocess as an owner would run it
(default threads, output to a pipe, so that every stage prints its plain lines). The manifold route is today's
recipe of docs/your_board.md: ``import ... --board eflesh --labelled K``, ``train --config
configs/train/contact_fewlabel.toml`` (which labels the unlabelled presses, then trains the network), ``export``
and ``evaluate``. Each command's wall time is taken from outside; train's is split into labelling and network at
the labeller's last stage line (the time that line arrived). Beside the times: the error of the calibrated model
on the run's test part (evaluate's RMSE, with its kNN on the same K labelled presses), the CPU time of all the
commands together (what the calibration costs whatever else runs; on two cores their wall time cannot be much
below it, as the labeller and the network each run on one thread), the longest stretch in
which a command printed nothing, what the train command itself said it took (its "train in all"), and the cores
other processes kept busy meanwhile (a shared machine slows every stage). Another route (a twin's fit-board ->
simulate -> train) is one more function in ``ROUTES``, returning its commands and the results file its last
one writes. Prints the table and writes it with the JSON (``docs/results/benchmarks/calibrate_time.{json,md}``).
It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchmarks._common import machine_info, publish
from benchmarks.fewlabel_k import RUNS, UNITS
from tactile_manip.bench.machine import cpu_counters, other_load

GOAL_S = 600.0  # the whole calibration, import to evaluate, on two cores
STAGES = ("import", "label", "train", "export", "evaluate")  # the manifold route's; a route may add its own


@dataclass(frozen=True)
class Case:
    """One calibration to time: a run folder of ``runs``, K labelled presses drawn with ``seed``, files in
    ``work``."""

    runs: Path
    run: str
    k: int
    seed: int
    work: Path


@dataclass(frozen=True)
class Step:
    """One command of a route: ``tactile-manip *argv``, its time counted to ``stage``; where ``split`` is given
    (a stage and a pattern), the command's time up to the last output line matching the pattern counts to that
    stage instead."""

    stage: str
    argv: tuple[str, ...]
    split: tuple[str, str] | None = None


def manifold_route(case: Case) -> tuple[list[Step], Path]:
    """Today's few-label recipe (docs/your_board.md): its commands, and the evaluate results file they write."""
    flags, _ = RUNS[case.run]
    name = f"{case.run}_{case.k}_{case.seed}"
    data, model, run = case.work / f"{name}.npz", case.work / f"{name}.onnx", case.runs / case.run
    evaluated = case.work / f"ev_{name}"
    return [
        Step("import", ("import", "--readings-csv", str(run / "sensor_post_baselines.csv"), "--labels-csv",
                        str(run / "states.csv"), *flags, "--board", "eflesh", "--labelled", str(case.k), "--seed",
                        str(case.seed), "--out", str(data))),
        Step("train", ("train", "--config", "configs/train/contact_fewlabel.toml", "--data", str(data), "--out",
                       str(case.work / name)), split=("label", r"^labelling: .* in [0-9.]+ s$")),
        Step("export", ("export", "--checkpoint", str(case.work / name / "best.pt"), "--out", str(model), "--data",
                        str(data))),
        Step("evaluate", ("evaluate", "--data", str(data), "--model", f"ours={model}", "--out", str(evaluated))),
    ], evaluated / "results.json"


ROUTES: dict[str, Callable[[Case], tuple[list[Step], Path]]] = {"manifold": manifold_route}


def run_step(step: Step, program: tuple[str, ...] = (sys.executable, "-m", "tactile_manip")) -> dict[str, Any]:
    """Run one command (``program`` with ``step.argv``); its wall time split by stage, its CPU time, its longest
    silence, its output lines."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.monotonic()
    stamped: list[tuple[float, str]] = []
    with subprocess.Popen([*program, *step.argv], stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, env=env) as child:
        for line in child.stdout:
            stamped.append((time.monotonic() - start, line.rstrip("\n")))
    wall = time.monotonic() - start
    done = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (done.ru_utime - used.ru_utime) + (done.ru_stime - used.ru_stime)
    if child.returncode:
        tail = "\n".join(text for _, text in stamped[-20:])
        raise SystemExit(f"tactile-manip {' '.join(step.argv)} failed ({child.returncode}):\n{tail}")
    moments = [0.0, *(t for t, _ in stamped), wall]
    stages = {step.stage: wall}
    if step.split is not None:
        marks = [t for t, text in stamped if re.match(step.split[1], text)]
        if marks:
            stages = {step.split[0]: marks[-1], step.stage: wall - marks[-1]}
    return {"stages": stages, "wall_s": wall, "cpu_s": cpu,
            "longest_silence_s": max(b - a for a, b in itertools.pairwise(moments)),
            "lines": [text for _, text in stamped]}


def claimed_total_s(lines: list[str]) -> float | None:
    """What the train command said it took in all ("train in all 4.2 min"), in seconds."""
    for text in lines:
        found = re.search(r"train in all ([0-9.]+) (s|min)", text)
        if found:
            return round(float(found.group(1)) * (60.0 if found.group(2) == "min" else 1.0), 1)
    return None


def time_case(route: str, case: Case) -> dict[str, Any]:
    """One calibration: every stage's wall time, the total against the goal, the test error."""
    steps, results = ROUTES[route](case)
    before = cpu_counters()
    stages: dict[str, float] = {}
    silences, claimed, cpu = [], None, 0.0
    for step in steps:
        done = run_step(step)
        cpu += done["cpu_s"]
        for stage, seconds in done["stages"].items():
            stages[stage] = stages.get(stage, 0.0) + seconds
        silences.append(done["longest_silence_s"])
        claimed = claimed_total_s(done["lines"]) if step.argv[0] == "train" else claimed
        print(f"  {step.argv[0]}: {done['wall_s']:.1f} s wall, {done['cpu_s']:.1f} s CPU", flush=True)
    figure = RUNS[case.run][1]
    methods = json.loads(results.read_text())["methods"]
    error = {m: float(methods[m][figure] if figure in methods[m] else methods[m]["rmse"][figure])
             for m in ("ours", "kNN")}
    total = sum(stages.values())
    return {"stages_s": {k: round(v, 1) for k, v in stages.items()}, "total_s": round(total, 1),
            "cpu_s": round(cpu, 1),
            "within_goal": total <= GOAL_S, "longest_silence_s": round(max(silences), 1),
            "train_says_s": claimed, "error": error, "figure": figure,
            "other_load": other_load(before, cpu_counters())}


def markdown(report: dict[str, Any]) -> str:
    stages = [*STAGES, *dict.fromkeys(s for row in report["cases"] for s in row["stages_s"] if s not in STAGES)]
    head = ["run", "route", "K", "seed", *(f"{s} s" for s in stages), "total", "CPU", f"<= {GOAL_S / 60:.0f} min",
            "longest silence s", "error (ours)", "kNN", "other cores busy"]
    title = f"\nWall time of the calibration, per stage (machine load at start {report['machine']['load_average']})\n"
    lines = [title, "| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for row in report["cases"]:
        other = (row["other_load"] or {}).get("other_processes_cores")
        lines.append("| " + " | ".join([
            row["run"].split("_")[0], row["route"], str(row["k"]), str(row["seed"]),
            *(f"{row['stages_s'][s]:.0f}" if s in row["stages_s"] else "-" for s in stages),
            f"{row['total_s'] / 60:.1f} min",
            f"{row['cpu_s'] / 60:.1f} min",
            "yes" if row["within_goal"] else "no", f"{row['longest_silence_s']:.0f}",
            f"{row['error']['ours']:.3f} {UNITS[row['figure']].split()[0]}", f"{row['error']['kNN']:.3f}",
            "-" if other is None else f"{other:.2f}"]) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=Path, required=True, help="folder holding the eFlesh run folders")
    p.add_argument("--run", nargs="+", choices=list(RUNS), default=list(RUNS), help="which runs (default: both)")
    p.add_argument("--route", nargs="+", choices=list(ROUTES), default=list(ROUTES), help="which routes (all)")
    p.add_argument("--k", type=int, default=25, help="labelled presses (25)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--out", type=Path, default=Path("docs/results/benchmarks/calibrate_time.json"))
    args = p.parse_args(argv)
    report: dict[str, Any] = {"machine": machine_info(), "goal_s": GOAL_S, "cases": []}
    with tempfile.TemporaryDirectory() as tmp:
        for run in args.run:
            for route in args.route:
                for seed in args.seeds:
                    print(f"{run} {route} K={args.k} seed {seed}:", flush=True)
                    work = Path(tmp) / f"{run}_{route}_{seed}"
                    work.mkdir()
                    row = time_case(route, Case(args.runs, run, args.k, seed, work))
                    report["cases"].append({"run": run, "route": route, "k": args.k, "seed": seed, **row})
                    args.out.parent.mkdir(parents=True, exist_ok=True)  # each case kept as it ends: a long
                    args.out.write_text(json.dumps(report, indent=2) + "\n")  # run cut short keeps its cases
    publish(report, args.out, markdown)
    args.out.with_suffix(".md").write_text(markdown(report).strip() + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
