"""How well one reading of the SuperMag board can place and weigh a known probe: a bound, and a plain MLP.

    python -m benchmarks.contact_probe_bound --data contact_probe.npz
    python -m benchmarks.contact_probe_bound --data contact_probe.npz --bound-presses 0   # the MLP only

Two measurements for the known probe of ``configs/dataset/contact_probe.toml`` (a 6 mm cylinder on the
nominal sensor, 2-15 N):

- **Cramer-Rao bound.** At ``--bound-presses`` poses drawn from the config's ranges, the Jacobian of the
  noise-free reading (48 channels) with respect to the press's six unknowns (x, y, yaw, two tilts, force),
  by central differences through the simulator, and the Fisher information of a reading whose channels carry
  independent Gaussian noise of the chip's noise and the per-press drift together (variance noise^2 +
  drift^2). Through the Jacobian of the targets (the centre of pressure ``x_mm``, ``y_mm`` and ``force_n``)
  it bounds the variance of any unbiased estimator from one reading; the RMSE bound is the root of its mean
  over the poses.
- **A plain MLP trained to convergence.** Two hidden layers of 128 ReLU units (torch, one thread, seeded),
  standardised field in, standardised ``x_mm``, ``y_mm``, ``force_n`` out, Adam (lr 1e-3, batch 200,
  cosine decay over ``--epochs``) on the squared error, keeping the weights of the best validation epoch;
  once with the centre of pressure as the position target, once with the centroid of the contact patch
  (the extra ``contact_centroid_mm``, where the dataset has it).

Prints markdown and writes docs/results/benchmarks/contact_probe_bound.json; asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import fit_best_mse, machine_info, publish
from tactile_manip.data import load_dataset
from tactile_manip.sim.dataset import load_dataset_config
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.shapes import make_indenter

# central-difference steps of (x mm, y mm, yaw rad, tilt x rad, tilt y rad, force as a share of the force)
STEPS = (0.05, 0.05, math.radians(0.5), math.radians(0.1), math.radians(0.1), 0.05)


def press_values(pair: SensorPair, probe: Any, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free reading (48,) uT and targets (x_mm, y_mm, force_n) of one press ``theta`` (6,)."""
    pose = IndenterPose(x_mm=theta[0], y_mm=theta[1], yaw_rad=theta[2], tilt_x_rad=theta[3], tilt_y_rad=theta[4])
    s = pair.press(probe, pose, float(theta[5]), np.random.default_rng(0), render_depth=False)
    return s.field_change_ut.reshape(-1).astype(np.float64), np.array([*s.pressure.centroid_mm, s.force_n])


def cramer_rao(config: str | Path, presses: int, seed: int) -> dict[str, Any]:
    """Mean Cramer-Rao variance of x_mm, y_mm and force_n over ``presses`` poses of ``config``'s ranges."""
    cfg = load_dataset_config(config)
    spec = cfg.objects[0]
    pair, probe = SensorPair(cfg.sim, seed=cfg.sensor_seed), make_indenter(spec.name, **spec.kwargs)
    chip, pr = cfg.sim.chip, cfg.poses
    var = np.tile([chip.noise_xy_ut ** 2 + chip.drift_ut ** 2] * 2 + [chip.noise_z_ut ** 2 + chip.drift_ut ** 2],
                  16)                                                    # (48,) uT^2 per channel
    rng = np.random.default_rng(seed)
    bounds = []
    for _ in range(presses):
        tilt = math.radians(pr.tilt_deg)
        theta = np.array([rng.uniform(-pr.offset_mm, pr.offset_mm), rng.uniform(-pr.offset_mm, pr.offset_mm),
                          math.radians(rng.uniform(*pr.yaw_deg)), rng.uniform(-tilt, tilt), rng.uniform(-tilt, tilt),
                          rng.uniform(*pr.force_n)])
        jac, tjac = np.zeros((48, 6)), np.zeros((3, 6))                  # reading and targets per unknown
        for k, step in enumerate(STEPS):
            h = np.zeros(6)
            h[k] = step * (theta[5] if k == 5 else 1.0)
            (fp, tp), (fm, tm) = press_values(pair, probe, theta + h), press_values(pair, probe, theta - h)
            jac[:, k], tjac[:, k] = (fp - fm) / (2 * h[k]), (tp - tm) / (2 * h[k])
        fisher = jac.T @ (jac / var[:, None])                            # (6, 6)
        bounds.append(np.diag(tjac @ np.linalg.pinv(fisher) @ tjac.T))   # (3,) variances
    b = np.array(bounds)
    return {"presses": presses, "x_mm": float(np.sqrt(b[:, 0].mean())), "y_mm": float(np.sqrt(b[:, 1].mean())),
            "position_2d_mm": float(np.sqrt((b[:, 0] + b[:, 1]).mean())), "force_n": float(np.sqrt(b[:, 2].mean())),
            "noise_ut_per_channel": [float(np.sqrt(v)) for v in var[:3]]}


def plain_mlp(readings: np.ndarray, targets: np.ndarray, split: np.ndarray, *, epochs: int,
              seed: int) -> dict[str, Any]:
    """Validation and test RMSE of a plain MLP from ``readings`` (N, 48) to ``targets`` (N, 3: x, y, force)."""
    import torch

    torch.set_num_threads(1)
    torch.manual_seed(seed)
    tr, va = split == "train", split == "val"
    xm, xs = readings[tr].mean(0), readings[tr].std(0) + 1e-9
    ym, ys = targets[tr].mean(0), targets[tr].std(0)
    z = torch.tensor((readings - xm) / xs, dtype=torch.float32)
    y = torch.tensor((targets - ym) / ys, dtype=torch.float32)
    net = torch.nn.Sequential(torch.nn.Linear(z.shape[1], 128), torch.nn.ReLU(), torch.nn.Linear(128, 128),
                              torch.nn.ReLU(), torch.nn.Linear(128, y.shape[1]))
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, epochs)
    gen = torch.Generator().manual_seed(seed)
    best_epoch = fit_best_mse(net, opt, sched, z, y, tr, va, epochs=epochs, batch_size=200, gen=gen)
    with torch.no_grad():
        pred = net(z).numpy() * ys + ym
    out: dict[str, Any] = {"best_epoch": best_epoch}
    for name in ("val", "test"):
        err = pred[split == name] - targets[split == name]
        out[name] = {"x_mm": float(np.sqrt((err[:, 0] ** 2).mean())), "y_mm": float(np.sqrt((err[:, 1] ** 2).mean())),
                     "position_2d_mm": float(np.sqrt((err[:, :2] ** 2).sum(1).mean())),
                     "force_n": float(np.sqrt((err[:, 2] ** 2).mean()))}
    return out


def markdown(report: dict[str, Any]) -> str:
    lines = [f"# Known probe: bound and plain MLP ({report['data']}, {report['train_presses']} training presses)",
             "", "| estimate | x RMSE mm | y RMSE mm | 2-D RMSE mm | force RMSE N |", "|---|---|---|---|---|"]
    b = report.get("cramer_rao")
    if b:
        lines.append(f"| Cramer-Rao bound ({b['presses']} poses) | {b['x_mm']:.3f} | {b['y_mm']:.3f} | "
                     f"{b['position_2d_mm']:.3f} | {b['force_n']:.3f} |")
    for name, r in report["plain_mlp"].items():
        t = r["test"]
        lines.append(f"| plain MLP, {name} (test; best epoch {r['best_epoch']}) | {t['x_mm']:.3f} | {t['y_mm']:.3f} | "
                     f"{t['position_2d_mm']:.3f} | {t['force_n']:.3f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", required=True, help="a simulated known-probe dataset (.npz)")
    parser.add_argument("--config", default="configs/dataset/contact_probe.toml",
                        help="the dataset config whose probe, sensor and pose ranges the bound uses")
    parser.add_argument("--bound-presses", type=int, default=40, help="poses of the bound (0: skip it)")
    parser.add_argument("--epochs", type=int, default=400, help="epochs of the plain MLP")
    parser.add_argument("--out", default="docs/results/benchmarks/contact_probe_bound.json")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    start = time.perf_counter()
    data = load_dataset(args.data)
    readings = data.readings.reshape(len(data), -1).astype(np.float64)
    force = data.target("force_n").astype(np.float64)[:, None]
    positions = {"centre of pressure": np.c_[data.target("x_mm"), data.target("y_mm")]}
    if data.has("contact_centroid_mm"):
        positions["centroid of the contact patch"] = data.extra("contact_centroid_mm")
    report: dict[str, Any] = {"data": Path(args.data).name, "train_presses": int((data.split == "train").sum()),
                              "plain_mlp": {name: plain_mlp(readings, np.c_[p.astype(np.float64), force], data.split,
                                                            epochs=args.epochs, seed=args.seed)
                                            for name, p in positions.items()}}
    if args.bound_presses:
        report["cramer_rao"] = cramer_rao(args.config, args.bound_presses, args.seed)
    report.update(seconds=round(time.perf_counter() - start, 1), machine=machine_info())
    publish(report, Path(args.out), markdown)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
