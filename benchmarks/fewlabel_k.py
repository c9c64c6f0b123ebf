"""Contact error against the number of labelled presses K, on the eFlesh characterisation runs.

    python -m benchmarks.fewlabel_k --runs ../shared/data/eflesh_dev            # K = 10, 25, 100, all; seeds 0, 1
    python -m benchmarks.fewlabel_k --runs ../shared/data/eflesh_dev --run normal_20250401_014340 --k 25

For each run (the spatial run's 2-D position, the normal run's force) and each K, the commands a board owner
runs: ``tactile-manip import ... --board eflesh --labelled K --seed S`` (chronological 80/20 split; K training
presses keep their labels, the other training presses stay unlabelled), ``train --config
configs/train/contact_fewlabel.toml``, ``export`` and ``evaluate``. Evaluate's own kNN (k = 5) and plain MLP,
fitted on the same K labelled presses, stand beside it. K = all is the whole training part labelled (the recipe
is then configs/train/contact.toml). Writes a JSON, a markdown table and a plot of error against K
(default ``docs/results/contact/fewlabel_k.*``; ``--update`` keeps the cases of that report this call does not
measure). It measures; it asserts nothing. Each command runs on one thread: a case takes about 1 CPU-minute
(the network), 4 for the spatial run's few labels (the labeller's leave-one-out refits), and about that in wall
time on an idle machine; on two cores other work kept 1.5 cores busy, 1.7 and 9 minutes
(``benchmarks.calibrate_time`` times each stage).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks._common import machine_info, publish

RUNS = {  # run folder -> (import flags, the figure read from evaluate)
    "spatial_20250316_155729": (["--label-columns", "time_s,x_mm,y_mm,z_mm", "--contact", "z_mm < 145.1",
                                 "--targets", "x_mm,y_mm"], "position_rmse_mm"),
    "normal_20250401_014340": (["--label-columns", "time_s,x_mm,y_mm,z_mm,force_gf", "--missing", "-1",
                                "--targets", "force_n"], "force_n"),
}
UNITS = {"position_rmse_mm": "mm (2-D position)", "force_n": "N (normal force)"}
METHODS = {"ours": "few-label recipe", "kNN": "kNN (k = 5)", "MLP": "plain MLP"}


def _cli(*args: str) -> None:
    done = subprocess.run([sys.executable, "-m", "tactile_manip", *args], capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"tactile-manip {' '.join(args)} failed:\n{done.stderr[-2000:]}")


def run_case(runs: Path, run: str, k: str, seed: int, work: Path) -> dict[str, float]:
    """One run at one K and seed: RMSE of our recipe and of evaluate's kNN and MLP on the test split."""
    flags, figure = RUNS[run]
    name = f"{run}_{k}_{seed}"
    data, model = work / f"{name}.npz", work / f"{name}.onnx"
    labelled = [] if k == "all" else ["--labelled", k, "--seed", str(seed)]
    _cli("import", "--readings-csv", str(runs / run / "sensor_post_baselines.csv"), "--labels-csv",
         str(runs / run / "states.csv"), *flags, "--board", "eflesh", *labelled, "--out", str(data))
    config = "configs/train/contact.toml" if k == "all" else "configs/train/contact_fewlabel.toml"
    _cli("train", "--config", config, "--data", str(data), "--out", str(work / name))
    _cli("export", "--checkpoint", str(work / name / "best.pt"), "--out", str(model), "--data", str(data))
    _cli("evaluate", "--data", str(data), "--model", f"ours={model}", "--out", str(work / f"ev_{name}"))
    methods = json.loads((work / f"ev_{name}" / "results.json").read_text())["methods"]
    return {m: float(methods[m][figure] if figure in methods[m] else methods[m]["rmse"][figure]) for m in METHODS}


def markdown(report: dict[str, Any]) -> str:
    lines = []
    for run, rows in report["runs"].items():
        figure = RUNS[run][1]
        lines += [f"\n{run}: test RMSE, {UNITS[figure]}, mean over seeds {report['seeds']}\n",
                  "| labelled presses K | " + " | ".join(METHODS.values()) + " |",
                  "|---" * (len(METHODS) + 1) + "|"]
        for k, row in rows.items():
            lines.append(f"| {k} | " + " | ".join(f"{row['mean'][m]:.3f}" for m in METHODS) + " |")
    return "\n".join(lines)


def plot(report: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(report["runs"]), figsize=(5.5 * len(report["runs"]), 4.2), squeeze=False)
    for ax, (run, rows) in zip(axes[0], report["runs"].items()):
        ks = list(rows)
        xs = [report["train_presses"][run] if k == "all" else int(k) for k in ks]
        for m, label in METHODS.items():
            ax.plot(xs, [rows[k]["mean"][m] for k in ks], "o-", label=label)
        ax.set_xscale("log")
        ax.set_xticks(xs, [f"{k}" for k in ks])
        ax.set_xlabel("labelled presses K")
        ax.set_ylabel(f"test RMSE, {UNITS[RUNS[run][1]]}")
        ax.set_title(run.split("_")[0])
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=Path, required=True, help="folder holding the eFlesh run folders")
    p.add_argument("--k", nargs="+", default=["10", "25", "100", "all"], help="labelled presses (or all)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    p.add_argument("--run", nargs="+", choices=list(RUNS), default=list(RUNS), help="which runs (default: both)")
    p.add_argument("--out", type=Path, default=Path("docs/results/contact/fewlabel_k.json"))
    p.add_argument("--update", action="store_true",
                   help="keep the cases of the report already at --out that this call does not measure")
    args = p.parse_args(argv)
    report: dict[str, Any] = {"machine": machine_info(), "seeds": args.seeds, "runs": {}, "train_presses": {}}
    if args.update and args.out.is_file():
        kept = json.loads(args.out.read_text())
        report["runs"], report["train_presses"] = kept["runs"], kept["train_presses"]
    with tempfile.TemporaryDirectory() as tmp:
        for run in args.run:
            report["runs"].setdefault(run, {})
            report["train_presses"][run] = sum(1 for _ in open(args.runs / run / "states.csv")) * 4 // 5
            for k in args.k:
                seeds = args.seeds[:1] if k == "all" else args.seeds
                per_seed = {s: run_case(args.runs, run, k, s, Path(tmp)) for s in seeds}
                mean = {m: sum(r[m] for r in per_seed.values()) / len(per_seed) for m in METHODS}
                report["runs"][run][k] = {"per_seed": per_seed, "mean": mean}
                print(f"{run} K={k}: " + ", ".join(f"{m} {v:.3f}" for m, v in mean.items()), flush=True)
    publish(report, args.out, markdown)
    args.out.with_suffix(".md").write_text(markdown(report).strip() + "\n")
    plot(report, args.out.with_suffix(".png"))
    print(f"wrote {args.out.with_suffix('.md')}, {args.out.with_suffix('.png')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
