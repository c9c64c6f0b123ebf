"""Experiment: the contact's angle read straight from the reading, against the image route, on unseen rods.

    python -m benchmarks.direct_angle          # trains in about a minute on 2 cores (300 epochs); needs torch

The Cramer-Rao bounds of ``benchmarks/angle_information.py`` say that one reading of ``data/robust.npz``'s
unseen rods carries the rod's angle to about a degree or better at any force, on any drawn sensor, while the
image route (reconstruct with the CVAE, then the paper's PCA) gets about 80 % of them within 5 deg. This
script measures how much of that gap a small learned regressor that skips the image closes. It is an
experiment, not a shipped method: nothing in the package uses it.

The regressor: an MLP (3 x 256, ReLU) from the reading's pattern (the 48 channels over their norm) and the
norm's logarithm to (cos 2a, sin 2a) of the contact's principal axis; the angle is half the output's
argument. Trained on the train splits of ``data/supermag.npz`` and ``data/robust.npz`` (no rods: they are
held out), each label the PCA angle of the true depth image (what the image route would find on a perfect
reconstruction), each sample weighted by that PCA's confidence (round contacts teach nothing), under the
sensor's dihedral symmetries drawn at random (a quarter turn adds 90 deg, a mirror negates the angle).
Tested on the unseen rods against their true yaw: the 600 of data/robust.npz (2-15 N, drawn sensors) per
force band, and the 240 of data/supermag.npz (10-11 N, nominal sensor), beside the image route with
``--model`` on the same presses and the paper's PCA on the true (VBTS) depth image: what the image route
would reach with a perfect reconstruction. Prints markdown, writes docs/results/benchmarks/direct_angle.json.
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.data import load_dataset
from tactile_manip.perception import TactilePoseEstimator, load_reconstructor, wrap_axial
from tactile_manip.evaluation.images import rod_estimates
from tactile_manip.perception.pose import angle_from_image

FORCE_BANDS_N = ((2.0, 5.0), (5.0, 8.0), (8.0, 11.0), (11.0, 15.0))


def features(readings: np.ndarray) -> np.ndarray:
    """(N, 49): the reading's 48 channels over their norm, and log10 of the norm (uT)."""
    flat = readings.reshape(len(readings), -1).astype(np.float64)
    norm = np.linalg.norm(flat, axis=1, keepdims=True) + 1e-6
    return np.concatenate([flat / norm, np.log10(norm)], axis=1).astype(np.float32)


def labelled(data, split: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Readings, PCA angles of the true images (rad) and their confidences, for presses with a defined angle."""
    idx = data.indices(split)
    depth = data.depth_mm(idx)
    keep, angle, conf = [], [], []
    for k, img in enumerate(depth):
        est = angle_from_image(img, pixel_mm=data.image.pixel_mm)
        if est.defined:
            keep.append(k)
            angle.append(est.angle_rad)
            conf.append(est.confidence)
    return data.readings[idx[keep]], np.array(angle), np.array(conf)


def train(readings: np.ndarray, angle: np.ndarray, weight: np.ndarray, *, epochs: int, seed: int):
    import torch
    from torch import nn

    from tactile_manip.learning.angle_head.train import symmetric

    torch.manual_seed(seed)
    torch.set_num_threads(2)
    net = nn.Sequential(nn.Linear(49, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, 256),
                        nn.ReLU(), nn.Linear(256, 2))
    opt = torch.optim.AdamW(net.parameters(), lr=1e-3, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, epochs)
    rng = np.random.default_rng(seed)
    w = torch.as_tensor(weight, dtype=torch.float32)
    for _ in range(epochs):
        x, a = symmetric(readings, angle, rng)
        x = torch.as_tensor(features(x))
        target = torch.as_tensor(np.stack([np.cos(2 * a), np.sin(2 * a)], 1), dtype=torch.float32)
        for batch in torch.randperm(len(x)).split(256):
            loss = (w[batch] * ((net(x[batch]) - target[batch]) ** 2).sum(1)).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        sched.step()
    return net.eval()


def predict(net, readings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Angles (rad) and output lengths (a confidence) of the regressor."""
    import torch

    with torch.no_grad():
        out = net(torch.as_tensor(features(readings))).numpy()
    return 0.5 * np.arctan2(out[:, 1], out[:, 0]), np.hypot(out[:, 0], out[:, 1])


def shares(errors: np.ndarray, force: np.ndarray | None) -> dict[str, Any]:
    row = {"presses": int(errors.size), "within_5": float(np.mean(errors <= 5)),
           "within_2": float(np.mean(errors <= 2)), "median_deg": float(np.median(errors)),
           "p95_deg": float(np.percentile(errors, 95))}
    if force is not None:
        row["by_force"] = {f"{lo:g}-{hi:g} N": float(np.mean(errors[(force >= lo) & (force < hi)] <= 5))
                           for lo, hi in FORCE_BANDS_N}
    return row


def evaluate(net, estimator, data, force_bands: bool) -> dict[str, Any]:
    """The direct regressor, the image route and the PCA of the true image on the test split's rods."""
    idx, _, image_err = rod_estimates(data, data.indices("test"), estimator)
    angle, _ = predict(net, data.readings[idx])
    yaw = data.extra("pose")[idx, 2]
    direct_err = np.degrees(np.abs(wrap_axial(angle - yaw)))
    truth = [angle_from_image(img, pixel_mm=data.image.pixel_mm) for img in data.depth_mm(idx)]
    truth_err = np.array([math.degrees(abs(wrap_axial(t.angle_rad - y))) if t.defined else 90.0
                          for t, y in zip(truth, yaw)])
    force = data.extra("force_n")[idx] if force_bands else None
    return {"direct": shares(direct_err, force), "image": shares(image_err, force),
            "PCA of the true image": shares(truth_err, force)}


def markdown(report: dict[str, Any]) -> str:
    lines = [f"Direct angle regressor against the image route ({report['model']}); trained on "
             f"{report['train_presses']} presses in {report['train_seconds']:.0f} s.", "",
             "| test set | method | within 5 deg | within 2 deg | median / p95 deg | within 5 deg at 2-5 / 5-8 / 8-11 "
             "/ 11-15 N |", "|---|---|---|---|---|---|"]
    for name, res in report["results"].items():
        for method, r in res.items():
            bands = " / ".join(f"{v:.1%}" for v in r["by_force"].values()) if "by_force" in r else "-"
            lines.append(f"| {name} ({r['presses']}) | {method} | {r['within_5']:.1%} | {r['within_2']:.1%} | "
                         f"{r['median_deg']:.2f} / {r['p95_deg']:.1f} | {bands} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="experiments/model_variants/supermag_robust.onnx",
                        help="the image route to compare with")
    parser.add_argument("--epochs", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="docs/results/benchmarks/direct_angle.json")
    args = parser.parse_args()
    robust, paper = load_dataset("data/robust.npz"), load_dataset("data/supermag.npz")
    parts = [labelled(d, "train") for d in (paper, robust)]
    readings, angle, conf = (np.concatenate([p[k] for p in parts]) for k in range(3))
    start = time.perf_counter()
    net = train(readings, angle, conf, epochs=args.epochs, seed=args.seed)
    seconds = time.perf_counter() - start
    estimator = TactilePoseEstimator(load_reconstructor(args.model, threads=2))
    results = {"data/robust.npz unseen rods": evaluate(net, estimator, robust, True),
               "data/supermag.npz unseen rods": evaluate(net, estimator, paper, False)}
    publish({"machine": machine_info(), "model": args.model, "train_presses": int(len(readings)),
             "train_seconds": seconds, "epochs": args.epochs, "results": results}, args.out, markdown)


if __name__ == "__main__":
    main()
