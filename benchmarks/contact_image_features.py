"""Does the reconstructed image help a contact network on unseen objects? The reading alone against the reading
and the pose model's image.

    python -m benchmarks.contact_image_features --data contact_unseen.npz robust.npz

The same network (3 x 256 GELU, dropout 0.1, AdamW, cosine decay, mean-squared error on the standardised
``x_mm``, ``y_mm`` and ``force_n``; the epoch of the best validation error) is trained twice on the train
split of the datasets given: on the reading (the 48 field values and each chip's log norm), and on the reading
plus the pose model's reconstruction pooled to 20 x 20 cells (each cell the mean depth of 10 x 10 pixels, 1 mm
on the SuperMag pad). Both are tested on the first dataset's test split. Prints markdown and writes
docs/results/benchmarks/contact_image_features.json; asserts nothing; about five minutes on one core.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
from tqdm import tqdm

from benchmarks._common import fit_best_mse, machine_info, publish
from tactile_manip.data import load_datasets
from tactile_manip.perception.reconstruct import OnnxReconstructor

TARGETS = ("x_mm", "y_mm", "force_n")
POOL = 10  # pixels per pooled cell


def pooled_images(model: OnnxReconstructor, readings: np.ndarray, batch: int = 256) -> np.ndarray:
    """(N, (H / POOL) * (W / POOL)) mean depth per cell of each reading's reconstruction, mm."""
    out = []
    for s in tqdm(range(0, len(readings), batch), desc="reconstructing", leave=False):
        images = model.reconstruct_batch(readings[s:s + batch].astype(np.float32))
        n, h, w = images.shape
        out.append(images.reshape(n, h // POOL, POOL, w // POOL, POOL).mean((2, 4)).reshape(n, -1))
    return np.concatenate(out).astype(np.float32)


def train_and_test(x: np.ndarray, y: np.ndarray, train: np.ndarray, val: np.ndarray, test: np.ndarray, *,
                   epochs: int, seed: int) -> dict[str, Any]:
    """Test RMSE per target and the 2-D position RMSE of the network trained on ``x[train]``."""
    import torch

    torch.manual_seed(seed)
    mu, sd = x[train].mean(0), x[train].std(0) + 1e-6
    xs = torch.from_numpy((x - mu) / sd)
    ym, ys = y[train].mean(0), y[train].std(0)
    yt = torch.from_numpy((y - ym) / ys)
    width = 256
    net = torch.nn.Sequential(torch.nn.Linear(x.shape[1], width), torch.nn.GELU(), torch.nn.Dropout(0.1),
                              torch.nn.Linear(width, width), torch.nn.GELU(), torch.nn.Dropout(0.1),
                              torch.nn.Linear(width, width), torch.nn.GELU(), torch.nn.Linear(width, y.shape[1]))
    opt = torch.optim.AdamW(net.parameters(), 1e-3, weight_decay=1e-3)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, epochs)
    best_epoch = fit_best_mse(net, opt, sched, xs, yt, train, val, epochs=epochs, batch_size=128)
    net.eval()
    with torch.no_grad():
        err = net(xs[test]).numpy() * ys + ym - y[test]
    rmse = {n: float(np.sqrt(np.mean(err[:, k] ** 2))) for k, n in enumerate(TARGETS)}
    position = float(np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2)))
    return {"best_epoch": best_epoch, "rmse": rmse, "rmse_2d_mm": position}


def compute(args: argparse.Namespace) -> dict[str, Any]:
    import torch

    torch.set_num_threads(1)
    data = load_datasets(args.data, images=False)
    first = len(load_datasets(args.data[:1], images=False))
    train, val = data.indices("train"), data.indices("val")
    test = data.indices("test")
    test = test[test < first]
    y = np.stack([data.target(n) for n in TARGETS], 1).astype(np.float32)
    flat = data.readings.reshape(len(data), -1).astype(np.float32)
    reading = np.concatenate([flat, np.log1p(np.linalg.norm(data.readings, axis=-1).reshape(len(data), -1))], 1)
    start = time.perf_counter()
    image = pooled_images(OnnxReconstructor(args.pose, image_symmetry="stored"), data.readings)  # as published
    out: dict[str, Any] = {"machine": machine_info(), "data": list(args.data), "pose": args.pose,
                           "train": int(len(train)), "val": int(len(val)), "test": int(len(test)),
                           "reconstruct_s": round(time.perf_counter() - start, 1), "results": {}}
    for name, x in (("reading", reading), ("reading + pooled image", np.concatenate([reading, image], 1))):
        out["results"][name] = train_and_test(x.astype(np.float32), y, train, val, test, epochs=args.epochs, seed=0)
    return out


def markdown(report: dict[str, Any]) -> str:
    lines = [f"Contact network on {', '.join(report['data'])}: trained on {report['train']} presses, tested on "
             f"{report['test']} unseen-object presses of the first; image from {report['pose']}.", "",
             "| input | force RMSE N | 2-D RMSE mm | best epoch |", "|---|---|---|---|"]
    for name, r in report["results"].items():
        lines.append(f"| {name} | {r['rmse']['force_n']:.3f} | {r['rmse_2d_mm']:.3f} | {r['best_epoch']} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", nargs="+", required=True, help="labelled datasets; the first one's test split")
    parser.add_argument("--pose", default="models/supermag.onnx", help="the image model")
    parser.add_argument("--epochs", type=int, default=150)
    parser.add_argument("--out", default="docs/results/benchmarks/contact_image_features.json")
    args = parser.parse_args()
    publish(compute(args), args.out, markdown)


if __name__ == "__main__":
    main()
