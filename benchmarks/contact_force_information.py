"""What one reading of the SuperMag board can tell about the normal force when the object's shape is unknown.

    python -m benchmarks.contact_force_information --data data/contact_unseen.npz
    python -m benchmarks.contact_force_information --data data/contact_probe.npz --out probe_force.json

Two measurements on a simulated contact dataset (``configs/dataset/contact_*.toml``), both on its test split:

- **Ablation.** The same regressor (standardised field, its direction and log norm -> force; an MLP of two
  hidden layers of 128 ReLU units, scikit-learn, seeded) trained on the training and validation splits with
  the reading alone,
  and with quantities a reading does not give added as inputs: the true indentation depth (what a perfect depth
  reconstruction would supply), the true contact area (the object's shape where it touches), the drawn skin's
  modulus (its stiffness), and these together (each as its logarithm). What an input buys is how much force
  error it removes. Beside them, the layer's elastic model without the reading: log force linear in the logs
  of the true depth, area and modulus (the route "force from the reconstructed depth", with a perfect depth).
- **Nearly identical readings.** For every test press, the training press nearest to it in the standardised
  feature space: the force difference of the closest pairs (the nearest 10 % and 25 % by distance) over sqrt 2
  estimates the spread of force among presses that give the same reading, an irreducible error that no
  estimator from that reading can go under (an estimate, since "nearly identical" is not identical).

Prints markdown and writes docs/results/benchmarks/contact_force_information.json; asserts nothing.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.data import load_dataset

CLOSEST_SHARES = (0.10, 0.25)


def reading_features(readings: np.ndarray) -> np.ndarray:
    """(N, F): the field, its direction and log norm, as the contact network's ``field_direction`` features."""
    flat = readings.reshape(len(readings), -1).astype(np.float64)
    norm = np.linalg.norm(flat, axis=1, keepdims=True)
    return np.concatenate([flat, flat / np.maximum(norm, 1e-6), np.log1p(norm)], axis=1)


def side_inputs(data) -> dict[str, np.ndarray]:
    """Quantities a reading does not give, each (N, 1) as its logarithm (force goes as their product in the
    layer's elastic model: modulus x area x depth / thickness), where the dataset records them."""
    out = {"depth": data.target("depth_mm")}
    if data.has("contact_area_mm2"):
        out["area"] = data.extra("contact_area_mm2")
    names = list(data.provenance.get("sensor_param_names", []))
    if data.has("sensor_params") and "layer.skin_modulus_kpa" in names:
        out["modulus"] = data.extra("sensor_params")[:, names.index("layer.skin_modulus_kpa")]
    return {k: np.log(np.maximum(np.asarray(v, np.float64), 1e-3))[:, None] for k, v in out.items()}


def fit_rmse(x: np.ndarray, y: np.ndarray, train: np.ndarray, test: np.ndarray, seed: int) -> float:
    from sklearn.neural_network import MLPRegressor

    mu, sd = x[train].mean(0), x[train].std(0) + 1e-9
    ym, ys = y[train].mean(), y[train].std()
    net = MLPRegressor(hidden_layer_sizes=(128, 128), max_iter=600, early_stopping=True, validation_fraction=0.1,
                       n_iter_no_change=30, learning_rate_init=1e-3, random_state=seed)
    net.fit((x[train] - mu) / sd, (y[train] - ym) / ys)
    pred = net.predict((x[test] - mu) / sd) * ys + ym
    return float(np.sqrt(np.mean((pred - y[test]) ** 2)))


def elastic_rmse(side: dict[str, np.ndarray], force: np.ndarray, train: np.ndarray, test: np.ndarray) -> float:
    """Force from the true depth, area and modulus alone: log F = a + b log d + c log A + e log E, least squares
    on the training presses (a flat punch on a thin layer gives b = c = e = 1)."""
    x = np.concatenate([np.ones((len(force), 1)), side["depth"], side["area"], side["modulus"]], axis=1)
    coef, *_ = np.linalg.lstsq(x[train], np.log(force[train]), rcond=None)
    return float(np.sqrt(np.mean((np.exp(x[test] @ coef) - force[test]) ** 2)))


def nearest_pairs(z: np.ndarray, force: np.ndarray, train: np.ndarray, test: np.ndarray) -> dict[str, Any]:
    """Force spread among each test press and its nearest training press in standardised feature space."""
    mu, sd = z[train].mean(0), z[train].std(0) + 1e-9
    a, b = (z[test] - mu) / sd, (z[train] - mu) / sd
    d2 = (a ** 2).sum(1)[:, None] + (b ** 2).sum(1)[None, :] - 2 * a @ b.T
    near = d2.argmin(1)
    dist = np.sqrt(np.maximum(d2[np.arange(len(a)), near], 0))
    diff = force[test] - force[train][near]
    rel = np.abs(diff) / np.maximum(force[test], 1e-6)
    order = np.argsort(dist)
    out: dict[str, Any] = {"all": {"pairs": int(len(a)), "force_sd_n": float(np.sqrt(np.mean(diff ** 2) / 2)),
                                   "median_rel": float(np.median(rel)), "max_distance": float(dist.max())}}
    for share in CLOSEST_SHARES:
        k = order[:max(2, int(round(share * len(a))))]
        out[f"closest {share:.0%}"] = {"pairs": int(len(k)), "force_sd_n": float(np.sqrt(np.mean(diff[k] ** 2) / 2)),
                                       "median_rel": float(np.median(rel[k])), "max_distance": float(dist[k].max())}
    return out


def markdown(report: dict[str, Any]) -> str:
    lines = [f"dataset {report['data']}: {report['train']} train / {report['test']} test presses, "
             f"force {report['force_range_n'][0]:.1f}-{report['force_range_n'][1]:.1f} N (test sd "
             f"{report['test_force_sd_n']:.2f} N)", "",
             "| inputs | force RMSE N (test) |", "|---|---|"]
    lines += [f"| {name} | {rmse:.3f} |" for name, rmse in report["ablation"].items()]
    lines += ["", "| nearest training press of each test press | pairs | force spread (RMS diff / sqrt 2) N | "
              "median relative difference | largest distance (std units) |", "|---|---|---|---|---|"]
    lines += [f"| {name} | {r['pairs']} | {r['force_sd_n']:.3f} | {r['median_rel']:.1%} | {r['max_distance']:.2f} |"
              for name, r in report["nearest"].items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", required=True, help="a simulated contact dataset (.npz) with force_n and depth_mm")
    parser.add_argument("--out", default="docs/results/benchmarks/contact_force_information.json")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    start = time.perf_counter()
    data = load_dataset(args.data)
    force = data.target("force_n").astype(np.float64)
    keep = force > 0                                          # presses that touch the pad
    train = np.flatnonzero(np.isin(np.arange(len(data)), np.concatenate([data.indices("train"),
                                                                        data.indices("val")])) & keep)
    test = np.flatnonzero(np.isin(np.arange(len(data)), data.indices("test")) & keep)
    z = reading_features(data.readings)
    side = side_inputs(data)
    sets = {"reading": []}
    for name in side:
        sets[f"reading + true {name}"] = [name]
    if "area" in side and "modulus" in side:
        sets["reading + true area + modulus"] = ["area", "modulus"]
    if len(side) > 1:
        sets["reading + " + " + ".join(f"true {n}" for n in side)] = list(side)
    ablation = {}
    for name, extra in sets.items():
        x = np.concatenate([z] + [side[e] for e in extra], axis=1)
        ablation[name] = fit_rmse(x, force, train, test, args.seed)
        print(f"  {name}: {ablation[name]:.3f} N", flush=True)
    if {"depth", "area", "modulus"} <= set(side):                 # the layer's elastic model, no reading
        ablation["elastic model only: log F linear in log depth, area, modulus"] = elastic_rmse(side, force, train,
                                                                                                 test)
    report = {"data": str(args.data), "train": int(len(train)), "test": int(len(test)),
              "force_range_n": [float(force[keep].min()), float(force[keep].max())],
              "test_force_sd_n": float(force[test].std()), "ablation": ablation,
              "nearest": nearest_pairs(z, force, train, test), "seconds": time.perf_counter() - start,
              "machine": machine_info()}
    publish(report, Path(args.out), markdown)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
