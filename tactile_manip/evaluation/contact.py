"""Evaluation of contact models on labelled presses: errors per target in its unit, against baselines.

For each method (exported contact models, and the baselines of :mod:`.contact_baselines` fitted on the same
dataset's training split), on the evaluated split: RMSE and MAE per target, the 2-D position RMSE where
``x_mm`` and ``y_mm`` are targets (the root mean squared Euclidean error), and for models with a sigma its
calibration: the share of errors within 1 and 2 sigma (a calibrated Gaussian: 68.3 % and 95.4 %). The same
per run (the dataset's groups) and, where ``force_n`` is a target, per band of the true force.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.data import PairedDataset
from tactile_manip.perception.contact import ContactEstimator
from tactile_manip.evaluation.contact_baselines import fit_predict_baselines, have_sklearn
from tactile_manip.perception.contact_context import context_windows

FORCE_BANDS_N = (0.0, 0.5, 5.0, 10.0, 20.0, float("inf"))   # edges of the true-force bands


def model_predictions(estimator: ContactEstimator, data: PairedDataset, index: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Mean and sigma (n, K) of an exported model on the samples ``index``, each with its context from the
    samples before it in its run (as the model was trained)."""
    context = estimator.metadata.get("context", {})
    time_s = data.extra("time_s") if data.has("time_s") else None
    windows = context_windows(data.readings, frames=estimator.context_frames,
                              max_gap_s=float(context.get("max_gap_s", 0.0)), time_s=time_s,
                              groups=data.groups)[index]
    means, sigmas = [], []
    for s in range(0, len(windows), 1024):
        m, sd = estimator.session.run(None, {"field_ut": windows[s:s + 1024]})
        means.append(m)
        sigmas.append(sd)
    return np.concatenate(means).astype(np.float64), estimator.calibrated_sigma(np.concatenate(sigmas))


def check_model_targets(estimator: ContactEstimator, data: PairedDataset, label: str) -> list[int]:
    """Columns of ``data.targets`` in the model's target order; ValueError when the data lack one."""
    missing = [n for n in estimator.target_names if n not in data.target_names]
    if missing:
        raise ValueError(f"model {label} ({estimator.path}) predicts {list(estimator.target_names)}; the dataset has "
                         f"no {missing} (its targets: {list(data.target_names)})")
    if data.readings.shape[1:] != estimator.input_shape:
        raise ValueError(f"model {label} takes readings of shape {estimator.input_shape}, the dataset has "
                         f"{data.readings.shape[1:]}")
    return [data.target_names.index(n) for n in estimator.target_names]


def metrics(pred: np.ndarray, true: np.ndarray, names: list[str], sigma: np.ndarray | None = None
            ) -> dict[str, Any]:
    """RMSE, MAE per target (unit of the target), 2-D position RMSE, and sigma coverage when ``sigma`` is given."""
    err = pred - true
    out: dict[str, Any] = {"n": int(len(true)),
                           "rmse": {n: float(np.sqrt(np.mean(err[:, k] ** 2))) for k, n in enumerate(names)},
                           "mae": {n: float(np.mean(np.abs(err[:, k]))) for k, n in enumerate(names)}}
    if "x_mm" in names and "y_mm" in names:
        ex, ey = err[:, names.index("x_mm")], err[:, names.index("y_mm")]
        out["position_rmse_mm"] = float(np.sqrt(np.mean(ex ** 2 + ey ** 2)))
    if sigma is not None and len(true):
        z = np.abs(err) / np.maximum(sigma, 1e-12)
        for level in (1, 2):
            inside = z <= level
            out[f"within_{level}_sigma"] = {**{n: float(inside[:, k].mean()) for k, n in enumerate(names)},
                                            "all": float(inside.mean())}
        out["mean_sigma"] = {n: float(sigma[:, k].mean()) for k, n in enumerate(names)}
    return out


def evaluate_contact(data: PairedDataset, models: dict[str, ContactEstimator], *, split: str = "test",
                     baselines: bool = True, seed: int = 0) -> dict[str, Any]:
    """Results of every model and baseline on ``split`` (see the module docstring)."""
    test, train = data.indices(split), data.indices("train")
    names = list(data.target_names)
    true = data.targets[test].astype(np.float64)
    preds: dict[str, tuple[np.ndarray, np.ndarray | None, list[str]]] = {}
    for label, est in models.items():
        cols = check_model_targets(est, data, label)
        mean, sigma = model_predictions(est, data, test)
        preds[label] = (mean, sigma, [names[c] for c in cols])
    if baselines:
        if not len(train):
            raise ValueError("the baselines are fitted on the training split, and the dataset has none "
                             "(give --no-baselines)")
        for label, p in fit_predict_baselines(data.readings[train], data.targets[train], data.readings[test],
                                              seed=seed).items():
            preds[label] = (p, None, names)
    groups = np.zeros(len(data), np.int64) if data.groups is None else data.groups
    run_names = _run_names(data)
    results: dict[str, Any] = {}
    for label, (mean, sigma, used) in preds.items():
        t = true[:, [names.index(n) for n in used]]
        entry = metrics(mean, t, used, sigma)
        entry["runs"] = {run_names.get(int(g), f"run{g}"): metrics(mean[groups[test] == g], t[groups[test] == g],
                                                                    used, None if sigma is None else
                                                                    sigma[groups[test] == g])
                         for g in np.unique(groups[test])}
        if "force_n" in used:
            f = t[:, used.index("force_n")]
            entry["force_bands"] = []
            for lo, hi in zip(FORCE_BANDS_N[:-1], FORCE_BANDS_N[1:]):
                sel = (f >= lo) & (f < hi)
                if sel.any():
                    entry["force_bands"].append({"band_n": [lo, hi], **metrics(
                        mean[sel], t[sel], used, None if sigma is None else sigma[sel])})
        results[label] = entry
    return {"split": split, "targets": names, "methods": results, "baseline_backend":
            ("scikit-learn" if have_sklearn() else "numpy") if baselines else None,
            "predictions": {k: {"mean": v[0], "targets": v[2]} for k, v in preds.items()}, "true": true}


def _run_names(data: PairedDataset) -> dict[int, str]:
    runs = data.provenance.get("runs") or []
    return {i: str(r.get("name", f"run{i}")) for i, r in enumerate(runs) if isinstance(r, dict)}


def markdown_table(report: dict[str, Any]) -> str:
    """One row per method: RMSE (and MAE) per target, position RMSE, sigma coverage; then per run and band."""
    names = report["targets"]
    methods = report["methods"]
    pos = any("position_rmse_mm" in m for m in methods.values())
    head = ["method", *(f"RMSE {n}" for n in names), *(["RMSE 2-D mm"] if pos else []),
            *(f"MAE {n}" for n in names), "within 1 sigma", "within 2 sigma"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for label, m in methods.items():
        lines.append("| " + " | ".join([label, *_row(m, names, pos)]) + " |")
    for label, m in methods.items():
        if len(m["runs"]) > 1:
            for run, r in m["runs"].items():
                lines.append("| " + " | ".join([f"{label}, {run}", *_row(r, names, pos)]) + " |")
    bands = [(label, b) for label, m in methods.items() for b in m.get("force_bands", [])]
    if bands:
        lines += ["", "| method | true force band N | n | RMSE force_n | within 1 sigma | within 2 sigma |",
                  "|---|---|---|---|---|---|"]
        for label, b in bands:
            lo, hi = b["band_n"]
            w1, w2 = (f"{100 * b[f'within_{k}_sigma']['force_n']:.1f} %" if f"within_{k}_sigma" in b else "-"
                      for k in (1, 2))
            lines.append(f"| {label} | {lo:g} - {hi:g} | {b['n']} | {b['rmse']['force_n']:.3f} | {w1} | {w2} |")
    return "\n".join(lines) + "\n"


def _row(m: dict[str, Any], names: list[str], pos: bool) -> list[str]:
    cell = [f"{m['rmse'][n]:.3f}" if n in m["rmse"] else "-" for n in names]
    if pos:
        cell.append(f"{m['position_rmse_mm']:.3f}" if "position_rmse_mm" in m else "-")
    cell += [f"{m['mae'][n]:.3f}" if n in m["mae"] else "-" for n in names]
    cell += [f"{100 * m[f'within_{k}_sigma']['all']:.1f} %" if f"within_{k}_sigma" in m else "-" for k in (1, 2)]
    return cell


def write_contact_report(out: str | Path, report: dict[str, Any], info: dict[str, Any]) -> None:
    """``out/table.md``, ``out/results.json`` and ``out/contact.png`` (predicted against true)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "table.md").write_text(markdown_table(report))
    body = {k: v for k, v in report.items() if k not in ("predictions", "true")}
    (out / "results.json").write_text(json.dumps({**info, **body}, indent=1) + "\n")
    plot_predictions(out / "contact.png", report)


def plot_predictions(path: Path, report: dict[str, Any]) -> None:
    """Predicted against true per target (one panel each; position as x and y panels): the models and the MLP
    baseline (the other baselines are in the table only; their clouds would hide the models')."""
    from tactile_manip.plots import _pyplot

    plt = _pyplot()
    names = report["targets"]
    shown = [k for k in report["predictions"] if k not in ("Linear", "kNN")]
    fig, axes = plt.subplots(1, len(names), figsize=(4.4 * len(names), 4.2), constrained_layout=True, squeeze=False)
    true = report["true"]
    for k, (ax, name) in enumerate(zip(axes[0], names)):
        lo, hi = float(true[:, k].min()), float(true[:, k].max())
        ax.plot([lo, hi], [lo, hi], color="0.3", lw=0.8, zorder=5)
        for label in reversed(shown):  # the first model on top
            p = report["predictions"][label]
            if name in p["targets"]:
                i = list(report["predictions"]).index(label)
                rmse = report["methods"][label]["rmse"][name]
                ax.scatter(true[:, k], p["mean"][:, p["targets"].index(name)], s=5,
                           alpha=0.35 if label == "MLP" else 0.6, color="0.55" if label == "MLP" else f"C{i}",
                           label=f"{label} (RMSE {rmse:.3g})", lw=0)
        ax.set_xlabel(f"true {name}")
        ax.set_ylabel(f"predicted {name}")
        handles, labels = ax.get_legend_handles_labels()
        ax.legend(handles[::-1], labels[::-1], fontsize=8, markerscale=3, loc="upper left")
    fig.savefig(path, dpi=110)
    plt.close(fig)
