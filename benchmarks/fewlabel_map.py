"""Where the few-label position error comes from: how well the map of the readings carries the press's place.

    python -m benchmarks.fewlabel_map --runs ../shared/data/eflesh_dev

The few-label recipe (:mod:`tactile_manip.learning.contact.fewlabel`) places unlabelled presses on a map of
their readings and fits the position on that map from the labelled ones. This benchmark separates what the map
loses from what a handful of labels cannot pin down, on the spatial run's training part (imported as
``benchmarks.fewlabel_k`` imports it, every label kept for scoring), at the labeller itself: the labels it gives
the unlabelled training presses, before any network learns from them.

1. The map with every label: for each of the recipe's maps, the RMSE of the best affine fit of its 2 and 3
   coordinates to the position (least squares over every training press), and a kNN (k = 5) from every
   other press, on the map's 3 coordinates and on the reading's direction itself (what the map was made from).
   The affine row is what the map gives when labels only have to set its scale, turn and offset; the kNN rows
   say how much of the place the map's coordinates still hold, against what the readings hold. A last row
   starts the refit at every press's true place, every press unlabelled, and scores where it leaves them: the
   refit's limit.
2. K presses labelled at random (``--seeds``): the labeller's RMSE on the other training presses, split into
   those inside the labelled presses' convex hull (interpolated) and those outside (extrapolated); for the
   labeller as ``train`` runs it (the map fits, then the refit on a smooth model of the field,
   :mod:`tactile_manip.learning.contact.field_inverse`) and for the map fits alone; and by the distance from
   each press to the nearest labelled one (bands ``NEAREST_MM``).
3. K presses labelled on an evenly spaced sqrt(K) x sqrt(K) grid over the pressed area (the training press
   nearest each grid point, as a user pressing at the marks of a printed grid would): the same RMSE.

Prints markdown and writes a JSON (default ``docs/results/contact/fewlabel_map.json``). It measures; it asserts
nothing. About 20 minutes on 2 CPU cores: the maps are built once, then each labelled draw takes about 2 minutes
(most of it the labeller's leave-one-out, which refits every press once per start and held-out label).
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from benchmarks.fewlabel_k import RUNS, _cli

RUN = "spatial_20250316_155729"
NEAREST_MM = (1.5, 3.0, 4.5)  # edges of the bands of distance to the nearest labelled press


def _rmse(pred: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((pred - truth) ** 2, axis=1)))) if len(truth) else math.nan


def _knn_rmse(features: np.ndarray, positions: np.ndarray, k: int = 5) -> float:
    """Leave-one-out kNN RMSE (k neighbours, mean of their positions) over every row."""
    from scipy.spatial import cKDTree

    _, idx = cKDTree(features).query(features, k=k + 1)
    return _rmse(positions[idx[:, 1:]].mean(axis=1), positions)


def map_fidelity(readings: np.ndarray, positions: np.ndarray,
                 maps: dict[str, np.ndarray] | None = None) -> dict[str, dict[str, float]]:
    """Per map of :func:`~tactile_manip.learning.contact.fewlabel.reading_maps` (``maps``, or built here): the
    affine fit's RMSE in 2 and 3 coordinates and the kNN RMSE on 3, with every press labelled;
    ``"direction itself"`` holds the kNN on the readings' unit vectors."""
    from tactile_manip.learning.contact.field_inverse import refine_places
    from tactile_manip.learning.contact.fewlabel import reading_maps

    out = {}
    for name, coords in (reading_maps(readings) if maps is None else maps).items():
        row = {}
        for dims in (2, 3):
            a = np.hstack([np.ones((len(coords), 1)), coords[:, :dims]])
            coef, *_ = np.linalg.lstsq(a, positions, rcond=None)
            row[f"affine_{dims}_mm"] = _rmse(a @ coef, positions)
        row["knn_3_mm"] = _knn_rmse(coords, positions)
        out[name] = row
    direction = readings / np.maximum(np.linalg.norm(readings, axis=1), 1e-12)[:, None]
    out["direction itself"] = {"knn_mm": _knn_rmse(direction, positions)}
    # the refit's own limit: started at every press's true place, every press unlabelled
    placed = refine_places(readings, positions, np.zeros(len(positions), bool))
    out["field model"] = {"inverted_mm": _rmse(placed, positions)}
    return out


def _finite_mean(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else math.nan


def grid_rows(positions: np.ndarray, k: int) -> np.ndarray:
    """Indices of the rows nearest an evenly spaced n x n grid (n = round(sqrt(k))) over the positions' extent,
    one per grid point, distinct."""
    n = max(2, round(math.sqrt(k)))
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    marks = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n)), -1).reshape(-1, 2)
    free = np.ones(len(positions), bool)
    rows = []
    for mark in marks:
        d = np.where(free, np.sum((positions - mark) ** 2, axis=1), np.inf)
        rows.append(int(np.argmin(d)))
        free[rows[-1]] = False
    return np.array(rows)


def labeller_error(readings: np.ndarray, positions: np.ndarray, rows: np.ndarray,
                   maps: dict[str, np.ndarray] | None = None, refine: bool = True) -> dict[str, Any]:
    """The labeller's RMSE on the unlabelled rows when ``rows`` are labelled (``maps``: the readings' maps, shared
    between draws; ``refine``: the map fits' places refitted on the field model, as ``train`` does): all of them,
    those inside the labelled positions' convex hull and those outside, and per band of distance to the nearest
    labelled press (``NEAREST_MM``: its share of the unlabelled rows and their RMSE), with the fits it chose."""
    from scipy.spatial import Delaunay, cKDTree

    from tactile_manip.learning.contact.fewlabel import PLACE_TARGETS, pseudo_labels

    lab = np.zeros(len(positions), bool)
    lab[rows] = True
    labels = pseudo_labels(readings, positions, lab, maps=maps, names=PLACE_TARGETS, refine=refine)
    inside = Delaunay(positions[lab]).find_simplex(positions) >= 0
    free = ~lab
    gap_mm = cKDTree(positions[lab]).query(positions[free])[0]
    band = np.digitize(gap_mm, NEAREST_MM)
    wrong = labels.values[free] - positions[free]
    nearest = [{"share": float(np.mean(band == b)),
                "rmse_mm": _rmse(wrong[band == b], np.zeros((int(np.sum(band == b)), 2)))}
               for b in range(len(NEAREST_MM) + 1)]
    return {"all_mm": _rmse(labels.values[free], positions[free]),
            "inside_mm": _rmse(labels.values[free & inside], positions[free & inside]),
            "outside_mm": _rmse(labels.values[free & ~inside], positions[free & ~inside]),
            "inside_share": float((free & inside).sum() / free.sum()), "by_nearest_label": nearest,
            "fits": list(labels.methods)}


def measure(readings: np.ndarray, positions: np.ndarray, k: int, seeds: list[int]) -> dict[str, Any]:
    """The three measurements of the module's docstring on ``readings`` (N, D) and ``positions`` (N, 2)."""
    from tactile_manip.learning.contact.fewlabel import reading_maps

    x = np.asarray(readings, np.float64).reshape(len(readings), -1)
    x = x[:, x.std(axis=0) > 0]
    y = np.asarray(positions, np.float64)
    maps = reading_maps(x)  # the readings' alone: built once for every draw of labels
    out: dict[str, Any] = {"presses": len(y), "k": k, "map_every_label": map_fidelity(x, y, maps)}
    for suffix, refine in (("", True), ("_map_only", False)):
        random = {s: labeller_error(x, y, np.random.default_rng(s).choice(len(y), k, replace=False), maps, refine)
                  for s in seeds}
        mean = {key: float(np.mean([r[key] for r in random.values()]))
                for key in ("all_mm", "inside_mm", "outside_mm")}
        mean["by_nearest_label"] = [
            {key: _finite_mean([r["by_nearest_label"][b][key] for r in random.values()])
             for key in ("share", "rmse_mm")} for b in range(len(NEAREST_MM) + 1)]
        out["random" + suffix] = {"per_seed": random, "mean": mean}
        out["grid" + suffix] = labeller_error(x, y, grid_rows(y, k), maps, refine)
    return out


def markdown(report: dict[str, Any]) -> str:
    lines = [f"\n{report['run']}, training part ({report['presses']} presses), RMSE of the 2-D position in mm\n",
             "Every press labelled:\n", "| map | affine, 2 coords | affine, 3 coords | kNN (k = 5), 3 coords |",
             "|---|---|---|---|"]
    for name, row in report["map_every_label"].items():
        if "affine_2_mm" in row:
            lines.append(f"| {name} | {row['affine_2_mm']:.2f} | {row['affine_3_mm']:.2f} | {row['knn_3_mm']:.2f} |")
    lines.append(f"| the reading's direction itself, no map | - | - | "
                 f"{report['map_every_label']['direction itself']['knn_mm']:.2f} |")
    if "field model" in report["map_every_label"]:
        lines.append(f"\nThe refit started at every press's true place, each press placed by it: "
                     f"{report['map_every_label']['field model']['inverted_mm']:.2f} mm (the refit's limit).")
    k = report["k"]
    lines += [f"\nThe labeller with {k} labelled presses, on the other training presses:\n",
              "| labelled presses | labeller | all | inside their hull | outside |", "|---|---|---|---|---|"]
    for suffix, how in (("", "map fits, refined on the field model"), ("_map_only", "map fits alone")):
        rnd, grid = report["random" + suffix], report["grid" + suffix]
        lines += [f"| {k} at random (mean of seeds {list(rnd['per_seed'])}) | {how} | {rnd['mean']['all_mm']:.2f} | "
                  f"{rnd['mean']['inside_mm']:.2f} | {rnd['mean']['outside_mm']:.2f} |",
                  f"| {k} on a grid | {how} | {grid['all_mm']:.2f} | {grid['inside_mm']:.2f} | "
                  f"{grid['outside_mm']:.2f} |"]
    bands = report["random"]["mean"].get("by_nearest_label")
    if bands:
        names = [f"< {NEAREST_MM[0]:g}", *(f"{a:g}-{b:g}" for a, b in zip(NEAREST_MM, NEAREST_MM[1:])),
                 f">= {NEAREST_MM[-1]:g}"]
        lines += [f"\nThe refined labeller, {k} at random, by distance to the nearest labelled press:\n",
                  "| distance (mm) | share of the presses | RMSE (mm) |", "|---|---|---|"]
        lines += [f"| {name} | {band['share']:.0%} | {band['rmse_mm']:.2f} |" for name, band in zip(names, bands)]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=Path, required=True, help="folder holding the eFlesh run folders")
    p.add_argument("--k", type=int, default=25, help="labelled presses (default 25)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5, 6, 7])
    p.add_argument("--out", type=Path, default=Path("docs/results/contact/fewlabel_map.json"))
    args = p.parse_args(argv)
    if args.k < 5:
        p.error(f"--k {args.k}: the labeller needs at least 5 labelled presses")
    from tactile_manip.data import load_dataset

    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "spatial.npz"
        _cli("import", "--readings-csv", str(args.runs / RUN / "sensor_post_baselines.csv"), "--labels-csv",
             str(args.runs / RUN / "states.csv"), *RUNS[RUN][0], "--board", "eflesh", "--out", str(data))
        dataset = load_dataset(data, images=False)
    train = dataset.split == "train"
    report = {"machine": machine_info(), "run": RUN, "seeds": args.seeds,
              **measure(dataset.readings[train], dataset.targets[train], args.k, args.seeds)}
    publish(report, args.out, markdown)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
