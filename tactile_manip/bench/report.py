"""The report's outputs: a markdown table, the JSON of every figure, and the Pareto plot of latency vs error.

The plot has two panels, PSNR on the unseen objects (higher is better) and the p95 rod angle error (lower is
better), each against the one-reading latency on one thread (p50, log scale; a thin bar reaches to p99).
The Pareto front joins the points no other point beats on both axes; the sensor's 8 ms frame period
(125 Hz) is drawn as the real-time line.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

PERIOD_MS = 8.0  # the MLX90393 array's frame period at 125 Hz
ONE_THREAD = ("numpy", "onnxruntime 1 thread", "onnxruntime int8 1 thread", "torch eager 1 thread")
PANELS = (("psnr_db", "PSNR on unseen objects [dB]", True), ("angle_p95_deg", "rod angle error p95 [deg]", False))


def pareto_front(points: Sequence[tuple[float, float]], *, higher_is_better: bool) -> list[int]:
    """Indices of the points (latency, value) that no other point beats on both, by rising latency.

    A point is on the front when every faster (or equally fast) point has a strictly worse value.
    """
    sign = -1.0 if higher_is_better else 1.0
    order = sorted(range(len(points)), key=lambda i: (points[i][0], sign * points[i][1]))
    front, best = [], math.inf
    for i in order:
        v = sign * points[i][1]
        if v < best:
            front.append(i)
            best = v
    return front


def plot_points(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows the plot shows: one-thread runtimes with a measured latency."""
    return [r for r in rows if r["runtime"] in ONE_THREAD and r.get("latency_p50_ms") is not None]


def point_label(row: dict[str, Any]) -> str:
    tag = {"onnxruntime int8 1 thread": " int8", "torch eager 1 thread": " torch"}.get(row["runtime"], "")
    return row["method"] + tag


def fronts(rows: Sequence[dict[str, Any]]) -> dict[str, list[str]]:
    """For each panel's metric, the labels of the points on its Pareto front, fastest first."""
    pts = plot_points(rows)
    out = {}
    for key, _, higher in PANELS:
        have = [r for r in pts if r.get(key) is not None]
        idx = pareto_front([(r["latency_p50_ms"], r[key]) for r in have], higher_is_better=higher)
        out[key] = [point_label(have[i]) for i in idx]
    return out


LABEL_OFFSET_PT = {"onnxruntime int8 1 thread": (4, -11), "torch eager 1 thread": (4, 10)}  # fp32 ones: (4, 3)


def plot_pareto(path: str | Path, report: dict[str, Any]) -> None:
    """Write the two-panel latency-vs-error figure (PNG) for ``report``."""
    from tactile_manip.plots import _pyplot

    plt = _pyplot()
    pts = plot_points(report["rows"])
    fig, axes = plt.subplots(1, 2, figsize=(15, 6), constrained_layout=True)
    for ax, (key, title, higher) in zip(axes, PANELS):
        _panel(ax, [r for r in pts if r.get(key) is not None], key, title, higher)
    axes[1].set_yscale("log")  # the angle error spans 1-90 deg: a log axis keeps the good models apart
    _plain_log_ticks(axes[1].yaxis)
    m = report["machine"]
    fig.suptitle(f"Speed vs error on {m['cpu_model']} ({m['usable_cores']} cores), "
                 f"{report['readings']['readings']} unseen readings", fontsize=10)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _panel(ax, have: list[dict[str, Any]], key: str, title: str, higher: bool) -> None:
    colours = {"numpy": "tab:grey", "onnxruntime 1 thread": "tab:blue", "onnxruntime int8 1 thread": "tab:orange",
               "torch eager 1 thread": "tab:green"}
    for runtime, colour in colours.items():
        mine = [r for r in have if r["runtime"] == runtime]
        if mine:
            ax.scatter([r["latency_p50_ms"] for r in mine], [r[key] for r in mine], color=colour, label=runtime,
                       zorder=3)
    for r in have:
        ax.plot([r["latency_p50_ms"], r["latency_p99_ms"]], [r[key]] * 2, color="0.6", lw=0.8, zorder=2)
        ax.annotate(point_label(r), (r["latency_p50_ms"], r[key]), textcoords="offset points",
                    xytext=LABEL_OFFSET_PT.get(r["runtime"], (4, 3)), fontsize=7)
    idx = pareto_front([(r["latency_p50_ms"], r[key]) for r in have], higher_is_better=higher)
    if idx:
        ax.step([have[i]["latency_p50_ms"] for i in idx], [have[i][key] for i in idx], where="post",
                color="tab:red", lw=1.2, zorder=1, label="Pareto front")
    ax.axvline(PERIOD_MS, color="k", ls="--", lw=1, label=f"sensor period {PERIOD_MS:g} ms (125 Hz)")
    ax.set_xscale("log")
    _plain_log_ticks(ax.xaxis)
    ax.set_xlabel("latency, one reading, 1 thread [ms] (p50; bar to p99)")
    ax.set_ylabel(title)
    ax.set_title(f"{title} vs latency ({'higher' if higher else 'lower'} is better)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")


def _plain_log_ticks(axis) -> None:
    """Decimal tick labels on a log axis, minor ones at 2 and 5 only."""
    from matplotlib import ticker

    plain = ticker.FuncFormatter(lambda v, _: f"{v:g}")
    axis.set_major_formatter(plain)
    axis.set_minor_locator(ticker.LogLocator(subs=(2.0, 5.0)))
    axis.set_minor_formatter(plain)


def _pair(a: float | None, b: float | None, fmt: str) -> str:
    return "-" if a is None else f"{a:{fmt}} / {b:{fmt}}"


def _accuracy_cells(r: dict[str, Any]) -> list[str]:
    if r.get("untrained"):
        return ["n/a (untrained)"] * 3
    if r.get("psnr_db") is None:
        return ["-"] * 3
    return [f"{r['psnr_db']:.2f}", f"{r['ssim']:.3f}", _pair(r["angle_median_deg"], r["angle_p95_deg"], ".1f")]


def _trial_cell(r: dict[str, Any]) -> str:
    t = r.get("trials")
    if r.get("untrained"):
        return "n/a (untrained)"
    if not t:
        return "-"
    return f"{t['successes']}/{t['n']} ({100 * t['wilson_low']:.0f}-{100 * t['wilson_high']:.0f} %)"


def _params(n: int | None) -> str:
    if n is None:
        return "-"
    return f"{n / 1e6:.2f} M" if n >= 1e5 else f"{n:,}"


def markdown_table(rows: Sequence[dict[str, Any]]) -> str:
    """One line per method and runtime."""
    head = ("| method | runtime | training | params | file MB | 1 reading p50 / p99 ms | batch 64 readings/s | "
            "pose p50 / p99 ms | PSNR dB | SSIM | rod angle median / p95 deg | trials success (95 % CI) |")
    lines = [head, "|---" * 12 + "|"]
    for r in rows:
        cells = [r["method"], r["runtime"], r.get("training", ""), _params(r.get("parameters")),
                 "-" if r.get("file_mb") is None else f"{r['file_mb']:g}",
                 _pair(r.get("latency_p50_ms"), r.get("latency_p99_ms"), ".2f"),
                 "-" if r.get("throughput_rps") is None else f"{r['throughput_rps']:.0f}",
                 _pair(r.get("pose_p50_ms"), r.get("pose_p99_ms"), ".2f"), *_accuracy_cells(r), _trial_cell(r)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


PAPER_METHOD = "paper"  # the row every pose latency is compared with


def pose_table(rows: Sequence[dict[str, Any]]) -> str:
    """Reading -> angle per method and runtime: one pad, two pads (per pair, one batched model run), the
    post-processing share of the one-pad time, and how many times faster than the paper preset on the same
    runtime (p50 against p50)."""
    paper = {r["runtime"]: r["pose_p50_ms"] for r in rows if r["method"] == PAPER_METHOD and r.get("pose_p50_ms")}
    lines = ["| method | runtime | 1 pad p50 / p99 ms | 2 pads p50 / p99 ms per pair | post-processing share | "
             "x faster than the paper preset (p50) |", "|---" * 6 + "|"]
    for r in rows:
        if r.get("pose_p50_ms") is None:
            continue
        share = r.get("postprocess_share")
        ratio = paper.get(r["runtime"])
        cells = [r["method"], r["runtime"], _pair(r["pose_p50_ms"], r["pose_p99_ms"], ".2f"),
                 _pair(r.get("pose_pair_p50_ms"), r.get("pose_pair_p99_ms"), ".2f"),
                 "-" if share is None else f"{share:.0%}",
                 "-" if ratio is None or r["method"] == PAPER_METHOD else f"{ratio / r['pose_p50_ms']:.0f}x"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def markdown_report(report: dict[str, Any]) -> str:
    """The whole report.md: what was measured on what, the table, the fronts and the notes."""
    m, lib, rd, s = report["machine"], report["libraries"], report["readings"], report["settings"]
    libs = ", ".join(f"{k} {v}" for k, v in lib.items() if v)
    trials = report.get("trials") or {}
    busy = m.get("during_run")
    quiet = (f" During the run other processes kept {busy['other_processes_cores']:.2f} cores busy on average and "
             f"the hypervisor took {100 * busy['steal_share']:.1f} % of the CPU time." if busy else "")
    out = [f"# Speed vs error ({'quick' if s.get('quick') else 'full'} run)", "",
           f"Machine: {m['cpu_model']}, {m['usable_cores']} usable cores (of {m['cpu_count']}), load average "
           f"{m.get('load_average')} at the start; Python {m['python']}; {libs}; code {m['code_version']}; "
           f"{m['time_utc']}; the report took {report['seconds']:.0f} s.{quiet}"
           + (f" Pose stage: {m['pose_stage']}." if m.get("pose_stage") else ""), "",
           f"Readings: {rd['source']} ({rd['readings']} readings, {rd['rod_readings']} of rods). Image metrics as "
           "`tactile-manip evaluate` (PSNR/SSIM data range 2 mm; rod angle error of the PCA pipeline against the "
           "true yaw). Latency: one reading through `Reconstructor.reconstruct`; pose: reading -> angle through "
           "`TactilePoseEstimator.estimate` on the rod readings; throughput: `reconstruct_batch` of 64.",
           "",
           (f"Trials: {trials['trials']} presentations of scene `{trials['scene']}` (seed {trials['seed']}, "
            f"success within {trials['tolerance_deg']:g} deg), one method at a time, as `tactile-manip trials`; the "
            "simulated sensor runs in real time, so its chip noise per frame depends on timing and a repeat can "
            "differ by a trial." if trials else "Trials: not run."), "",
           markdown_table(report["rows"]),
           "Rows of one model in fp32 (onnxruntime at any thread count, torch eager) share the accuracy computed "
           f"on the first one once their outputs agree within {report['share_tolerance_mm']:g} mm on "
           f"{s['parity_readings']} readings (`accuracy_from` and `parity_max_abs_mm` in report.json); accuracy "
           "passes use all cores where that gives the same outputs, trials use 1 thread as the trials command. "
           f"Baselines are 200x200 with the shipped linear fit. Sensor period: {PERIOD_MS:g} ms.", "",
           "Reading -> angle (`TactilePoseEstimator.estimate` on the rod readings; two pads: `estimate_many` of two "
           "readings, one batched model run, time per pair):", "",
           pose_table(report["rows"])]
    for key, title, _ in PANELS:
        out.append(f"Pareto front ({title} vs 1-thread latency): {', '.join(report['pareto'][key]) or '-'}")
    if report["notes"]:
        out += ["", "Notes:", *[f"- {n}" for n in report["notes"]]]
    return "\n".join(out) + "\n"


def write_report(out_dir: str | Path, report: dict[str, Any]) -> list[Path]:
    """Write report.md, report.json and pareto.png into ``out_dir``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "report.md", out / "report.json", out / "pareto.png"]
    paths[0].write_text(markdown_report(report), encoding="utf-8")
    paths[1].write_text(json.dumps(report, indent=1, default=_json_default) + "\n", encoding="utf-8")
    plot_pareto(paths[2], report)
    return paths


def _json_default(x: Any) -> Any:
    if hasattr(x, "item"):
        return x.item()
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")
