"""A run's report: ``summary.json``, a markdown summary, and two figures (matplotlib, Agg backend).

Files, written to the given folder (``TAG`` is empty for the run's own report and ``_<tol>deg``, e.g.
``_5deg``, when ``tactile-manip score`` re-scores a run, so reports at several tolerances sit side by side)::

    summary{TAG}.json                run info, tolerance, per-method results, paired comparisons, per object,
                                     with a contact model the estimated grip force per method ("grip_force",
                                     :mod:`tactile_manip.trials.grip_force`), and the sections of the run's
                                     task (``Task.report``: e.g. "lateral_error", "force_error")
    summary{TAG}.md                  the same as markdown tables
    errors{TAG}.png                  histogram of |error| (deg) per method over executed trials, tolerance line:
                                     a 0-10 deg zoom and the whole range on a log count axis
    success_vs_tolerance{TAG}.png    success rate vs tolerance 0-20 deg, Wilson 95 % bands, tolerance marked

matplotlib is imported inside the plotting functions, so importing this module is free.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.behaviours.registry import DEFAULT_TASK, task_class
from tactile_manip.behaviours.task import ReportSection, Task
from tactile_manip.trials.grip_force import GripForceSummary, grip_force_summary, markdown_lines
from tactile_manip.trials.record import OUTCOMES, TrialRecord
from tactile_manip.trials.stats import RunSummary, success_vs_tolerance, summarise, wilson_interval

SWEEP_MAX_DEG = 20.0
SWEEP_STEP_DEG = 0.1
ZOOM_DEG = 10.0  # the error histogram's left panel: where methods that mostly succeed differ
LINE_STYLES = ("-", "--", ":", "-.")  # one per method, so overlapping outlines stay apart in grey print too
RUN_KEYS = ("run_id", "config_hash", "code_version", "started_utc")  # copied from run.json into the summary
DEFAULT_RULE = Task.success_rule(())  # the success sentence a task's own replaces


def tolerance_tag(tolerance_rad: float) -> str:
    """File-name tag of a re-scored report, e.g. ``"_5deg"`` or ``"_2.5deg"``."""
    return f"_{math.degrees(tolerance_rad):.6g}deg"


def write_report(run_dir: str | Path, records: Sequence[TrialRecord], tolerance_rad: float, *,
                 title: str | None = None, tag: str = "", run_info: Mapping[str, Any] | None = None,
                 task: type[Task] | None = None) -> RunSummary:
    """Score ``records`` at ``tolerance_rad`` and write the report files (module docstring) to ``run_dir``.

    Args:
        run_dir: folder to write to (created if missing).
        records: the run's trial records.
        tolerance_rad: success tolerance on |final - target|, rad.
        title: heading of the markdown summary and the figures (default: the task's title).
        tag: appended to every file stem (see :func:`tolerance_tag`); empty for the run's own report.
        run_info: the run's ``run.json`` (id, config hash, code version), copied into the summary; its config
            also says whether the cell was simulated (then the grip force is scored against the applied force).
        task: the task the trials ran (default: :func:`task_of_run`); its sections and success rule join the
            report.

    Returns:
        The RunSummary the files show.
    """
    summary = summarise(records, tolerance_rad)
    out = Path(run_dir)
    out.mkdir(parents=True, exist_ok=True)
    run = {k: run_info[k] for k in RUN_KEYS if k in run_info} if run_info else {}
    grip = grip_force_summary(records, applied=_simulated(run_info))
    task = task or task_of_run(records, run_info)
    title = title or (task.title if task is not None else "Trials")
    sections: list[ReportSection] = task.report(records) if task is not None else []
    doc = {"title": title, "task": task.name if task is not None else _task_name(records), "run": run,
           "tolerance_rad": tolerance_rad, **summary.to_dict()}
    if grip:
        doc["grip_force"] = {m: asdict(s) for m, s in grip.items()}
    doc.update({section.key: section.data for section in sections})
    (out / f"summary{tag}.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    text = markdown_summary(summary, title=title, run_info=run, grip_force=grip)
    if task is not None:
        text = text.replace(DEFAULT_RULE, task.success_rule(records), 1)
    for section in sections:
        text = text.rstrip("\n") + f"\n\n## {section.heading}\n\n" + "\n".join(
            _table(list(section.columns), [list(row) for row in section.rows])) + "\n"
    (out / f"summary{tag}.md").write_text(text, encoding="utf-8")
    plot_errors(out / f"errors{tag}.png", records, tolerance_rad, title=title)
    plot_success_vs_tolerance(out / f"success_vs_tolerance{tag}.png", records, tolerance_rad, title=title)
    return summary


def task_of_run(records: Sequence[TrialRecord], run_info: Mapping[str, Any] | None = None) -> type[Task] | None:
    """The task a run's trials ran: the one its ``run.json`` config names, else the one its records name (the
    default task for records written before records named one); None when that task cannot be imported here
    (the report then has no sections of the task's own)."""
    config = (run_info or {}).get("config")
    ref = config.get("task") if isinstance(config, Mapping) else None
    for candidate in (ref, _task_name(records)):
        if isinstance(candidate, str):
            try:
                return task_class(candidate)
            except ValueError:
                continue
    return None


def _task_name(records: Sequence[TrialRecord]) -> str:
    return next((r.task for r in records if r.task), DEFAULT_TASK)


def _simulated(run_info: Mapping[str, Any] | None) -> bool:
    """Whether ``run_info``'s config ran on the simulated cell (False when unknown)."""
    config = (run_info or {}).get("config")
    robot = config.get("robot") if isinstance(config, Mapping) else None
    return isinstance(robot, Mapping) and robot.get("backend") == "twin"


def markdown_summary(summary: RunSummary, *, title: str = "Reorientation trials",
                     run_info: Mapping[str, Any] | None = None,
                     grip_force: Mapping[str, GripForceSummary] | None = None) -> str:
    """The summary as markdown: results per method, paired comparisons, outcomes and per-object counts, and
    the estimated grip force where the run had a contact model."""
    tol = summary.tolerance_deg
    lines = [f"# {title}", ""]
    if run_info:
        lines += [", ".join(f"{k} `{v}`" for k, v in run_info.items()), ""]
    lines += [f"{DEFAULT_RULE} {tol:.6g} deg ({math.radians(tol):.4g} rad); "
              f"{summary.n_records} trial records.", ""]
    lines += _table(["method", "success", "rate", "Wilson 95 % CI", "median abs err (deg)", "p95 abs err (deg)",
                     "abstained", "faults"],
                    [[m, f"{s.successes}/{s.n}", _pct(s.success_rate), f"{_pct(s.wilson_low)} - {_pct(s.wilson_high)}",
                      _deg(s.abs_error_median_deg), _deg(s.abs_error_p95_deg), str(s.abstentions), str(s.faults)]
                     for m, s in summary.methods.items()])
    if summary.paired:
        lines += ["", "## Paired comparison (trials both methods ran)", ""]
        lines += _table(["A", "B", "pairs", "both", "only A", "only B", "neither", "McNemar p (exact)"],
                        [[p.method_a, p.method_b, str(p.n_pairs), str(p.both), str(p.only_a), str(p.only_b),
                          str(p.neither), f"{p.mcnemar_p:.4g}"] for p in summary.paired])
    seen = [o for o in OUTCOMES if any(s.outcomes[o] for s in summary.methods.values())]
    lines += ["", "## Outcomes", ""]
    lines += _table(["method", *seen], [[m, *(str(s.outcomes[o]) for o in seen)]
                                        for m, s in summary.methods.items()])
    lines += ["", "## Per object (successes/trials)", ""]
    lines += _table(["object", *summary.methods],
                    [[obj, *(f"{by[m].successes}/{by[m].n}" if m in by else "-" for m in summary.methods)]
                     for obj, by in summary.per_object.items()])
    lines += markdown_lines(dict(grip_force or {}))
    return "\n".join(lines) + "\n"


def plot_errors(path: str | Path, records: Sequence[TrialRecord], tolerance_rad: float, *,
                title: str = "") -> None:
    """Write :func:`errors_figure` to ``path`` (PNG)."""
    from tactile_manip.plots import _pyplot

    plt = _pyplot()
    fig = errors_figure(records, tolerance_rad, title=title)
    try:
        fig.savefig(path, dpi=100)
    finally:
        plt.close(fig)


def errors_figure(records: Sequence[TrialRecord], tolerance_rad: float, *, title: str = ""):
    """|error| (deg) per method over executed trials, tolerance dashed, as two panels: a zoom on the first
    ``ZOOM_DEG`` (0.25 deg bins, where the methods that succeed differ) and the whole range on a log count
    axis (1 deg bins, so a tail of single trials shows). Methods are step outlines in distinct line styles;
    the legend gives each one's count, median and how many trials lie beyond the zoom."""
    from tactile_manip.plots import _pyplot

    plt = _pyplot()
    methods = dict.fromkeys(r.method for r in records)
    errors_deg = {m: np.degrees([abs(r.error_rad) for r in records if r.method == m and r.outcome == "done"])
                  for m in methods}
    tol_deg = math.degrees(tolerance_rad)
    zoom = max(ZOOM_DEG, 2.0 * tol_deg)
    top = max([SWEEP_MAX_DEG, tol_deg * 1.2, *(float(e.max()) for e in errors_deg.values() if e.size)])
    fig, (near, far) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True,
                                    gridspec_kw={"width_ratios": [3, 2]})
    for k, (m, e) in enumerate(errors_deg.items()):
        style = {"histtype": "step", "linewidth": 2, "linestyle": LINE_STYLES[k % len(LINE_STYLES)],
                 "color": f"C{k}"}
        near.hist(e, bins=np.linspace(0.0, zoom, int(round(zoom / 0.25)) + 1), **style,
                  label=_error_label(m, e, zoom))
        far.hist(e, bins=np.linspace(0.0, math.ceil(top), min(90, math.ceil(top)) + 1), **style)
    for ax in (near, far):
        ax.axvline(tol_deg, color="k", linestyle="--", linewidth=1, label=f"tolerance {tol_deg:.6g} deg")
        ax.set_xlabel("|final - target| [deg]")
    near.set_xlim(0.0, zoom)
    near.set_ylabel("trials")
    near.yaxis.get_major_locator().set_params(integer=True)
    near.set_title(f"0-{zoom:g} deg (0.25 deg bins; the legend counts those beyond)", fontsize=10)
    far.set_xlim(0.0, math.ceil(top))
    if any(e.size for e in errors_deg.values()):  # a log axis needs one count to show
        far.set_yscale("log")
    far.set_ylabel("trials (log)")
    far.set_title("whole range (1 deg bins)", fontsize=10)
    near.legend(fontsize=8, loc="upper right")
    fig.suptitle(f"{title}: final error" if title else "final error")
    return fig


def _error_label(method: str, errors_deg: np.ndarray, zoom_deg: float) -> str:
    if not errors_deg.size:
        return f"{method}: no executed trial"
    beyond = int(np.count_nonzero(errors_deg > zoom_deg))
    return (f"{method}: {errors_deg.size} executed, median {np.median(errors_deg):.2g} deg, "
            f"{beyond} beyond {zoom_deg:g} deg")


def plot_success_vs_tolerance(path: str | Path, records: Sequence[TrialRecord], tolerance_rad: float, *,
                              title: str = "") -> None:
    """Success rate vs tolerance (0-20 deg, wider if the tolerance is) with Wilson 95 % bands."""
    from tactile_manip.plots import _pyplot

    plt = _pyplot()
    tol_deg = math.degrees(tolerance_rad)
    sweep_deg = np.arange(0.0, max(SWEEP_MAX_DEG, tol_deg) + SWEEP_STEP_DEG / 2, SWEEP_STEP_DEG)
    rates = success_vs_tolerance(records, np.radians(sweep_deg))
    counts = {m: sum(r.method == m for r in records) for m in rates}
    fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
    try:
        for m, rate in rates.items():
            n = counts[m]
            bands = np.array([wilson_interval(int(round(x * n)), n) for x in rate])
            (line,) = ax.step(sweep_deg, rate, where="post", linewidth=2, label=f"{m} (n={n})")
            ax.fill_between(sweep_deg, bands[:, 0], bands[:, 1], step="post", alpha=0.2,
                            color=line.get_color(), linewidth=0)
        ax.axvline(tol_deg, color="k", linestyle="--", label=f"tolerance {tol_deg:.6g} deg")
        ax.set_xlim(0.0, sweep_deg[-1])
        ax.set_ylim(0.0, 1.02)
        ax.set_xlabel("tolerance on |final - target| [deg]")
        ax.set_ylabel("success rate (Wilson 95 % band)")
        ax.set_title(f"{title}: success vs tolerance" if title else "success vs tolerance")
        ax.legend(loc="lower right")
        fig.savefig(path, dpi=100)
    finally:
        plt.close(fig)


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header),
            *("| " + " | ".join(row) + " |" for row in rows)]


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def _deg(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"
