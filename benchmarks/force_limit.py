"""Where the force error of K labelled presses comes from on the eFlesh normal-force run, and what bounds it.

    python -m benchmarks.force_limit                       # the dev normal run, K = 25, 40 draws (about 2 min)
    python -m benchmarks.force_limit --k 10 --draws 20 --out /tmp/force_limit.json

The protocol of :mod:`benchmarks.twin_protocol`: the chronological 80/20 split of ``tactile-manip import``, every
fit on the first 80 % of the run's rows (their statistics too: scales, quantiles, principal axes), K labelled
presses drawn from them as ``import --labelled K --seed S`` draws them, scores (force RMSE, N) on the last 20 %.
Seeds 0 and 1 are the protocol's; ``--draws`` more seeds say how much one draw's luck weighs. It prints and writes:

- ``diagnosis``: the labeller's fit of the field norm (:mod:`~tactile_manip.learning.contact.fewlabel`; the old
  cubic and today's bent line) from K labels and from every label of the first 80 %, its error on the test tail
  while pressing in, springing back and holding still, per force band and per quarter of the tail, and its bias.
- ``limits``: every label (gradient boosting on the reading and the two frames before it: the floor the readings
  leave); an oracle that knows the stage's z, its speed and the run's clock (every label); a model that knows the
  all-label shape and takes only a gain and an offset from K labels; and the best that two families of smooth maps
  of the readings reach from K labels with their hyper-parameters picked on the test tail itself (optimistic, so a
  bound): a Gaussian-kernel ridge of the norm, its change and the run's clock, and the labeller's linear family
  with its ridge picked per draw.

It measures; it asserts nothing. Writes docs/results/contact/force_limit.{json,md,png}.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish

DEFAULT_RUN = Path(os.environ.get("TACTILE_MANIP_EFLESH_DIR", Path(__file__).resolve().parents[2] / "shared" / "data"
                                  / "eflesh_dev")) / "normal_20250401_014340"
GAMMAS = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0)  # kernel widths tried for the bound, on unit-spread features
ALPHAS = (0.01, 0.1, 1.0, 10.0)            # its ridges
RIDGES = np.logspace(-3, 3, 25)            # ridges of the linear family tried for its bound
BANDS_N = (0.0, 0.5, 5.0, 15.0, 25.0, 40.0)
RECENCY = 2.0                              # contact_fewlabel.toml's label_recency


def load_run(run: Path, work: Path) -> dict[str, Any]:
    """The run imported with every label (force and stage z), and what every fit needs, from its first 80 %."""
    import subprocess
    import sys

    from tactile_manip.data import load_dataset
    from tactile_manip.perception.contact_context import context_windows

    out = work / "normal_all.npz"
    if not out.is_file():
        subprocess.run([sys.executable, "-m", "tactile_manip", "import", "--readings-csv",
                        str(run / "sensor_post_baselines.csv"), "--labels-csv", str(run / "states.csv"),
                        "--label-columns", "time_s,x_mm,y_mm,z_mm,force_gf", "--missing", "-1", "--targets",
                        "force_n,z_mm", "--board", "eflesh", "--out", str(out)], check=True, capture_output=True)
    data = load_dataset(out, images=False)
    t = data.extra("time_s").astype(np.float64)
    windows = context_windows(data.readings, frames=3, max_gap_s=1.0, time_s=t)  # contact_fewlabel.toml's context
    flat = windows.reshape(len(data), 3, -1).astype(np.float64)
    train, test = data.indices("train"), data.indices("test")
    live = flat[train, 0].std(axis=0) > 0
    return {"x": flat[:, 0, live], "earlier": flat[:, -1, live], "middle": flat[:, 1, live], "t": t,
            "force": data.target("force_n").astype(np.float64), "z": data.target("z_mm").astype(np.float64),
            "train": train, "test": test}


def features(d: dict[str, Any]) -> dict[str, np.ndarray]:
    """The labeller's terms, every statistic from the first 80 %: the norm, its change, the readings' second and
    third principal axes, the run's elapsed share (of the first 80 %'s span)."""
    tr = d["train"]
    norm = np.linalg.norm(d["x"], axis=1)
    change = norm - np.linalg.norm(d["earlier"], axis=1)
    mean, spread = d["x"][tr].mean(axis=0), d["x"][tr].std(axis=0)
    z = (d["x"] - mean) / spread
    _, _, vt = np.linalg.svd(z[tr] - z[tr].mean(axis=0), full_matrices=False)
    axes = (z - z[tr].mean(axis=0)) @ vt[1:3].T
    axes /= axes[tr].std(axis=0)
    t = d["t"]
    return {"norm": norm / norm[tr].std(), "change": change / change[tr].std(), "axes": axes,
            "elapsed": (t - t[tr].min()) / np.ptp(t[tr])}


def labelled_rows(d: dict[str, Any], k: int, seed: int) -> np.ndarray:
    """The K training rows ``import --labelled K --seed S`` keeps the labels of (its draw, as a mask)."""
    from tactile_manip.data.probe_logs import hold_back_labels

    split = np.full(len(d["force"]), "test", dtype="U16")
    split[d["train"]] = "train"
    out, _ = hold_back_labels(split, np.zeros((len(split), 1)), {}, k, seed)
    return out == "train"


def norm_design(feat: dict[str, np.ndarray], train: np.ndarray, lab: np.ndarray, *, cubic: bool) -> np.ndarray:
    """The labeller's terms of the field norm (the old cubic, or the bent line with its knots from the first
    80 %'s norms and the labelled rows ``lab``), each of unit spread on the first 80 %."""
    from tactile_manip.learning.contact.fewlabel import norm_knots

    s = feat["norm"]
    if cubic:
        shape = np.c_[s ** 2, s ** 3]
    else:
        shape = np.maximum(s[:, None] - norm_knots(s[train], lab[train])[None], 0.0)
    terms = np.hstack([s[:, None], shape, np.c_[feat["change"], feat["change"] * s], feat["axes"]])
    return terms / terms[train].std(axis=0).clip(1e-12)


def shrunk_fit(design: np.ndarray, lab: np.ndarray, y: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The labeller's shrunk fit (:func:`~tactile_manip.learning.contact.fewlabel._shrunk`) on the rows ``lab``."""
    from tactile_manip.learning.contact.fewlabel import _shrunk

    return _shrunk(design, free=1, weights=weights)(lab, y)


def rmse(p: np.ndarray, y: np.ndarray, rows: np.ndarray) -> float:
    return float(np.sqrt(np.mean((p[rows] - y[rows]) ** 2)))


def breakdown(p: np.ndarray, d: dict[str, Any]) -> dict[str, Any]:
    """The test tail's error while pressing in, springing back and holding, per force band and per quarter."""
    te, f = d["test"], d["force"]
    speed = np.gradient(d["z"], d["t"])  # mm/s: a smaller z is a deeper press
    phases = {"pressing in": speed < -1e-3, "springing back": speed > 1e-3, "holding": np.abs(speed) <= 1e-3}
    out: dict[str, Any] = {"rmse": rmse(p, f, te), "bias": float(np.mean(p[te] - f[te])), "phases": {},
                           "bands": {}, "quarters": []}
    for name, mask in phases.items():
        rows = te[mask[te]]
        out["phases"][name] = {"rows": int(len(rows)), "rmse": rmse(p, f, rows), "bias": float(np.mean(p[rows] - f[rows]))}
    for lo, hi in zip(BANDS_N[:-1], BANDS_N[1:]):
        rows = te[(f[te] >= lo) & (f[te] < hi)]
        out["bands"][f"{lo:g}-{hi:g} N"] = {"rows": int(len(rows)), "rmse": rmse(p, f, rows),
                                          "bias": float(np.mean(p[rows] - f[rows]))}
    out["quarters"] = [rmse(p, f, q) for q in np.array_split(te, 4)]
    return out


def section_diagnosis(d: dict[str, Any], feat: dict[str, np.ndarray], k: int, draws: int) -> dict[str, Any]:
    from tactile_manip.learning.contact.fewlabel import recency_weights

    f, tr = d["force"], d["train"]
    weights = recency_weights(d["t"], RECENCY)
    every = np.zeros(len(f), bool)
    every[tr] = True
    out: dict[str, Any] = {}
    for name, cubic in (("cubic (before)", True), ("bent line", False)):
        errs, first = [], None
        for seed in range(max(draws, 2)):
            lab = labelled_rows(d, k, seed)
            p = shrunk_fit(norm_design(feat, tr, lab, cubic=cubic), lab, f, weights)
            errs.append(rmse(p, f, d["test"]))
            first = breakdown(p, d) if seed == 0 else first
        p_all = shrunk_fit(norm_design(feat, tr, every, cubic=cubic), every, f, weights)
        out[name] = {"seeds_0_1": float(np.mean(errs[:2])), "draws": len(errs), "mean": float(np.mean(errs)),
                     "median": float(np.median(errs)), "per_draw": errs, "seed_0": first,
                     "every_label": breakdown(p_all, d)}
        print(f"diagnosis {name}: K={k} seeds 0, 1 {np.mean(errs[:2]):.3f} N, {len(errs)} draws {np.mean(errs):.3f} N; "
              f"every label {out[name]['every_label']['rmse']:.3f} N", flush=True)
    return out


def section_limits(d: dict[str, Any], feat: dict[str, np.ndarray], k: int, draws: int) -> dict[str, Any]:
    from sklearn.ensemble import HistGradientBoostingRegressor

    f, tr, te = d["force"], d["train"], d["test"]
    scale = d["x"][tr].std(axis=0)
    frames = np.hstack([d["x"], d["middle"], d["earlier"]]) / np.tile(scale, 3)

    def boosted(x: np.ndarray) -> np.ndarray:
        return HistGradientBoostingRegressor(max_iter=400, learning_rate=0.05, random_state=0).fit(
            x[tr], f[tr]).predict(x)

    shape = boosted(frames)
    speed = np.gradient(d["z"], d["t"])
    out: dict[str, Any] = {"every_label_readings": rmse(shape, f, te),
                           "every_label_stage_z": rmse(boosted(d["z"][:, None]), f, te),
                           "every_label_stage_z_speed_clock": rmse(boosted(np.c_[d["z"], speed, feat["elapsed"]]), f, te)}
    seeds = range(max(draws, 2))
    masks = [labelled_rows(d, k, s) for s in seeds]
    gain = []
    for lab in masks:
        a = np.c_[np.ones(len(f)), shape]
        gain.append(rmse(a @ np.linalg.lstsq(a[lab], f[lab], rcond=None)[0], f, te))
    out["known_shape_gain_offset_from_k"] = {"seeds_0_1": float(np.mean(gain[:2])), "mean": float(np.mean(gain))}
    smooth = np.c_[feat["norm"], feat["change"], 2.0 * feat["elapsed"]]
    best = None
    for gamma in GAMMAS:
        for alpha in ALPHAS:
            errs = [rmse(_kernel_ridge(smooth, lab, f, gamma, alpha), f, te) for lab in masks]
            if best is None or np.mean(errs) < best["mean"]:
                best = {"mean": float(np.mean(errs)), "seeds_0_1": float(np.mean(errs[:2])), "gamma": gamma,
                        "alpha": alpha}
    out["kernel_ridge_picked_on_test"] = best
    errs = []
    for lab in masks:
        design = np.c_[np.ones(len(f)), norm_design(feat, tr, lab, cubic=False),
                       np.log1p(feat["elapsed"] / 0.3) * feat["norm"]]
        penalty = np.ones(design.shape[1])
        penalty[:2] = 0.0
        a = design[lab]
        errs.append(min(rmse(design @ np.linalg.solve(a.T @ a + np.diag(r * penalty + 1e-6), a.T @ f[lab]), f, te)
                        for r in RIDGES))
    out["linear_family_ridge_picked_on_test"] = {"mean": float(np.mean(errs)), "seeds_0_1": float(np.mean(errs[:2]))}
    for key, value in out.items():
        print(f"limit {key}: " + (f"{value:.3f} N" if isinstance(value, float) else
                                  f"seeds 0, 1 {value['seeds_0_1']:.3f} N, {len(masks)} draws {value['mean']:.3f} N"),
              flush=True)
    return out


def _kernel_ridge(x: np.ndarray, lab: np.ndarray, y: np.ndarray, gamma: float, alpha: float) -> np.ndarray:
    """An affine map of ``x`` plus a Gaussian-kernel ridge of its residuals, fitted on the rows ``lab``."""
    a = np.c_[np.ones(len(x)), x]
    coef = np.linalg.lstsq(a[lab], y[lab], rcond=None)[0]
    xl = x[lab]
    k = np.exp(-gamma * ((xl[:, None] - xl[None]) ** 2).sum(-1))
    w = np.linalg.solve(k + alpha * np.eye(len(xl)), y[lab] - a[lab] @ coef)
    return a @ coef + np.exp(-gamma * ((x[:, None] - xl[None]) ** 2).sum(-1)) @ w


def markdown(report: dict[str, Any]) -> str:
    k, diag, lim = report["k"], report["diagnosis"], report["limits"]
    lines = [f"# Force at K = {k} on {report['run']} (chronological 80/20; fits on the first 80 %; RMSE, N, on the "
             "last 20 %)", "", "## The labeller's fit of the field norm", "",
             f"| fit | seeds 0, 1 | {diag['bent line']['draws']} draws: mean | median | every label |",
             "|---|---|---|---|---|"]
    for name, row in diag.items():
        lines.append(f"| {name} | {row['seeds_0_1']:.3f} | {row['mean']:.3f} | {row['median']:.3f} | "
                     f"{row['every_label']['rmse']:.3f} |")
    lines += ["", "Where the bent line's error falls (seed 0, and every label):", "",
              "| part of the test tail | rows | seed 0 RMSE | bias | every label RMSE | bias |", "|---|---|---|---|---|---|"]
    one, every = diag["bent line"]["seed_0"], diag["bent line"]["every_label"]
    for group in ("phases", "bands"):
        for name, row in one[group].items():
            e = every[group][name]
            lines.append(f"| {name} | {row['rows']} | {row['rmse']:.3f} | {row['bias']:+.3f} | {e['rmse']:.3f} | "
                         f"{e['bias']:+.3f} |")
    lines.append("| quarters of the tail, in time | | " + " / ".join(f"{v:.2f}" for v in one["quarters"]) + " | | "
                 + " / ".join(f"{v:.2f}" for v in every["quarters"]) + " | |")
    lines += ["", "## Limits", "", "| what | seeds 0, 1 | mean of draws |", "|---|---|---|",
              f"| every label, the reading and 2 frames before it (boosted trees) | {lim['every_label_readings']:.3f} | - |",
              f"| every label, the stage z alone | {lim['every_label_stage_z']:.3f} | - |",
              f"| every label, the stage z, its speed and the run's clock | {lim['every_label_stage_z_speed_clock']:.3f} | - |"]
    names = {"known_shape_gain_offset_from_k": f"the all-label shape known, gain and offset from K = {k}",
             "kernel_ridge_picked_on_test": f"kernel ridge of norm, change and clock from K = {k}, width and ridge "
                                            "picked on the test tail",
             "linear_family_ridge_picked_on_test": f"the labeller's terms and a softening term from K = {k}, ridge "
                                                   "picked on the test tail per draw"}
    for key, name in names.items():
        lines.append(f"| {name} | {lim[key]['seeds_0_1']:.3f} | {lim[key]['mean']:.3f} |")
    return "\n".join(lines)


def plot(d: dict[str, Any], feat: dict[str, np.ndarray], k: int, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tactile_manip.learning.contact.fewlabel import recency_weights

    f, tr, te = d["force"], d["train"], d["test"]
    weights = recency_weights(d["t"], RECENCY)
    every = np.zeros(len(f), bool)
    every[tr] = True
    p_k = shrunk_fit(norm_design(feat, tr, labelled_rows(d, k, 0), cubic=False), labelled_rows(d, k, 0), f, weights)
    p_all = shrunk_fit(norm_design(feat, tr, every, cubic=False), every, f, weights)
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.2))
    minutes = (d["t"] - d["t"].min()) / 60
    for p, label in ((p_k, f"K = {k}, seed 0"), (p_all, "every label")):
        ax[0].plot(minutes, p - f, lw=0.6, label=label)
        ax[1].plot(f[te], (p - f)[te], ".", ms=2, label=label)
    ax[0].axvline(minutes[te[0]], color="k", lw=0.8)
    ax[0].set(xlabel="minutes into the run (test tail right of the line)", ylabel="label fit - load cell, N")
    ax[1].set(xlabel="load cell force, N (test tail)", ylabel="error, N")
    ax[2].scatter(feat["norm"][tr], f[tr], c=minutes[tr], s=2)
    ax[2].plot(feat["norm"][te], f[te], "r.", ms=1, alpha=0.4)
    ax[2].set(xlabel="field norm (unit spread)", ylabel="force, N", title="first 80 % by time; test tail red")
    for a in ax[:2]:
        a.legend()
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    import tempfile

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--run", type=Path, default=DEFAULT_RUN, help="the normal-force run folder")
    p.add_argument("--k", type=int, default=25, help="labelled presses")
    p.add_argument("--draws", type=int, default=40, help="draws of K labels (seeds 0 .. draws-1)")
    p.add_argument("--out", type=Path, default=Path("docs/results/contact/force_limit.json"))
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        d = load_run(args.run, Path(tmp))
    feat = features(d)
    report = {"machine": machine_info(), "run": args.run.name, "k": args.k, "draws": args.draws,
              "diagnosis": section_diagnosis(d, feat, args.k, args.draws),
              "limits": section_limits(d, feat, args.k, args.draws)}
    publish(report, args.out, markdown)
    args.out.with_suffix(".md").write_text(markdown(report).strip() + "\n")
    plot(d, feat, args.k, args.out.with_suffix(".png"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
