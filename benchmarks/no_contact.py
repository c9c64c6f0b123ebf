"""No contact, and readings that are no press: what the shipped models say of noise, uniform fields, idle pads and
light presses.

    python -m benchmarks.no_contact                       # about 2-3 minutes on one core
    python -m benchmarks.no_contact --poses 12 --out /tmp/no_contact.json

Two measures of ``TactileEstimator.load()`` (the shipped pose and contact models, and the SuperMag board's press
check, :mod:`tactile_manip.perception.press_check`):

1. **Readings no press makes**, 1000 of them (seed 1): 500 of white noise N(0, s) on every channel, s
   log-uniform from 1 to 500 uT; 250 uniform fields (one value on every channel) and 250 constant vectors (one
   (x, y, z) on every chip), of either sign and a size log-uniform from 1 to 2000 uT. Per kind: the mean angle
   confidence, and how many claim a contact with an answer (``in_contact`` and ``plausible`` both True).
2. **The simulated board**, on sensors and shapes nothing was tuned on: the six test rods (never in the press
   bank), each sensor its own draw of held-out seeds (pair seeds 7,000,000 on; the bank's are 1,100,000-1,299,999),
   the nominal sensor's parameters and sensors drawn from the simulator's full randomisation ranges (chip noise
   1.5-15 uT, drift 0-10 uT, gain 2-3x). Per pose (any yaw, up to 5 mm off centre, tilted up to 5 deg) one frame
   without a press (the sensor's drift and chip noise: a drift drawn per frame, as per press) and one frame of
   the rod at each force. Rates against force: detected (``in_contact``) and measured (``in_contact`` and
   ``plausible``: a force and a position given). The drawn sensors are judged twice: against the board's rated
   floor (the default), and against the sensor's own floor as its baseline measures it
   (``set_noise_floor(baseline.noise_ut)``, the std of 125 idle frames).

Prints markdown tables, writes the JSON (default ``docs/results/benchmarks/no_contact.json``), the tables beside
it (``.md``) and the rate curves (``.png``). It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one thread
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402
from benchmarks.bench_pose import RODS  # noqa: E402
from tactile_manip.perception import TactileEstimator  # noqa: E402
from tactile_manip.perception.press_check import DRIFT_ALLOWANCE_UT, FALSE_ALARM, MIN_LIKENESS  # noqa: E402
from tactile_manip.sim.objects import IndenterPose  # noqa: E402
from tactile_manip.sim.pair import SensorPair  # noqa: E402
from tactile_manip.boards import load_board  # noqa: E402
from tactile_manip.sim.params import for_board, randomise  # noqa: E402
from tactile_manip.sim.shapes import make_indenter  # noqa: E402

FORCES_N = (0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0)
PAIR_SEED = 7_000_000


def noise_readings(seed: int = 1) -> dict[str, np.ndarray]:
    """The 1000 readings of part 1 by kind, each (n, 4, 4, 3) uT."""
    rng = np.random.default_rng(seed)
    scale = np.exp(rng.uniform(0.0, math.log(500.0), 500))
    white = rng.standard_normal((500, 4, 4, 3)) * scale[:, None, None, None]
    size = np.exp(rng.uniform(0.0, math.log(2000.0), 250)) * rng.choice([-1.0, 1.0], 250)
    uniform = np.broadcast_to(size[:, None, None, None], (250, 4, 4, 3)).copy()
    direction = rng.standard_normal((250, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    vectors = direction * np.exp(rng.uniform(0.0, math.log(2000.0), 250))[:, None]
    constant = np.broadcast_to(vectors[:, None, None, :], (250, 4, 4, 3)).copy()
    return {"white noise, 1-500 uT": white, "uniform field, 1-2000 uT": uniform,
            "constant vector, 1-2000 uT": constant}


def judge_noise(estimator: TactileEstimator) -> list[dict[str, Any]]:
    rows = []
    for kind, readings in noise_readings().items():
        estimates = [estimator.estimate(r) for r in readings]
        confidence = np.array([e.angle.confidence for e in estimates])
        claims = sum(e.in_contact and e.plausible for e in estimates)
        rows.append({"kind": kind, "readings": len(readings), "mean_confidence": float(confidence.mean()),
                     "max_confidence": float(confidence.max()),
                     "in_contact": int(sum(e.in_contact for e in estimates)),
                     "implausible": int(sum(not e.plausible for e in estimates)), "claims_contact": int(claims)})
    return rows


def measured_noise_ut(pair: SensorPair, rng: np.random.Generator, frames: int = 125) -> np.ndarray:
    """(4, 4, 3) the per-channel std of ``frames`` idle frames, as a baseline measures it."""
    raw = np.stack([pair.chips.measure(pair.baseline_field_ut, rng).raw_ut for _ in range(frames)])
    return pair.to_reading(raw.std(axis=0))


def judge_board(estimator: TactileEstimator, poses: int, seed: int) -> dict[str, Any]:
    rods = [make_indenter(name, size_mm=size) for name, size in RODS]
    rng = np.random.default_rng(seed)
    counts: dict[str, dict[str, np.ndarray]] = {}
    rated = estimator.contact.press_check
    for sensor in ("nominal", "drawn", "drawn, own floor"):
        counts[sensor] = {k: np.zeros(len(FORCES_N) + 1, int) for k in ("frames", "detected", "measured")}
    for i in range(poses):
        drawn = i % 3 != 0  # two drawn sensors per nominal one
        nominal = for_board(load_board("supermag-4x4"))
        params = randomise(nominal, rng) if drawn else nominal
        pair = SensorPair(params, seed=PAIR_SEED + i)
        rod = rods[i % len(rods)]
        pose = IndenterPose(x_mm=rng.uniform(-5, 5), y_mm=rng.uniform(-5, 5), yaw_rad=rng.uniform(-math.pi, math.pi),
                            tilt_x_rad=math.radians(rng.uniform(-5, 5)), tilt_y_rad=math.radians(rng.uniform(-5, 5)))
        idle = pair.chips.measure(pair.baseline_field_ut, rng, drift_ut=pair.chips.draw_drift(rng))
        frames = [(0, pair.to_reading((idle.raw_ut - pair.baseline_ut).astype(np.float32)))]
        for k, force in enumerate(FORCES_N, start=1):
            sample = pair.press(rod, pose, force, rng, render_depth=False)
            if not sample.bottomed_out and sample.contact:
                frames.append((k, sample.field_ut))
        floors = [("nominal" if not drawn else "drawn", None)]
        if drawn:
            floors.append(("drawn, own floor", measured_noise_ut(pair, rng)))
        for sensor, floor in floors:
            estimator.contact.press_check = rated if floor is None else rated.with_noise(floor)
            estimator.pose.press_check = estimator.contact.press_check
            c = counts[sensor]
            for k, field in frames:
                e = estimator.estimate(field)
                c["frames"][k] += 1
                c["detected"][k] += e.in_contact
                c["measured"][k] += e.in_contact and e.plausible
    estimator.contact.press_check = estimator.pose.press_check = rated
    out = {}
    for sensor, c in counts.items():
        rows = []
        for k, force in enumerate((0.0, *FORCES_N)):
            n = int(c["frames"][k])
            rows.append({"force_n": force, "frames": n, "detected": float(c["detected"][k] / max(n, 1)),
                         "measured": float(c["measured"][k] / max(n, 1))})
        out[sensor] = rows
    return out


def markdown(report: dict[str, Any]) -> str:
    lines = [f"No contact and no press: `TactileEstimator.load()` (false-alarm rate {FALSE_ALARM:g} per idle frame "
             f"at the floor, drift allowance {DRIFT_ALLOWANCE_UT:g} uT, press likeness >= {MIN_LIKENESS:g})", "",
             "| readings | n | mean confidence | max confidence | in contact | no answer (plausible False) | "
             "contact claimed with an answer |", "|---|---|---|---|---|---|---|"]
    for r in report["noise"]:
        lines.append(f"| {r['kind']} | {r['readings']} | {r['mean_confidence']:.4f} | {r['max_confidence']:.3f} | "
                     f"{r['in_contact']} | {r['implausible']} | {r['claims_contact']} |")
    lines += ["", "Simulated SuperMag board, six unseen rods, held-out sensors: share of frames detected "
              "(`in_contact`) / measured (`in_contact` and `plausible`)", "",
              "| force N | " + " | ".join(report["board"]) + " |", "|---|" + "---|" * len(report["board"])]
    sensors = list(report["board"].values())
    for k, row in enumerate(sensors[0]):
        cells = [f"{s[k]['detected'] * 100:.1f} / {s[k]['measured'] * 100:.1f} % ({s[k]['frames']})" for s in sensors]
        label = "0 (no press)" if row["force_n"] == 0 else f"{row['force_n']:g}"
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def figure(report: dict[str, Any], path: Path) -> None:
    from tactile_manip.plots import _pyplot

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
    for j, (sensor, rows) in enumerate(report["board"].items()):
        force = [r["force_n"] for r in rows[1:]]
        ax.plot(force, [r["detected"] for r in rows[1:]], "o-", color=f"C{j}", label=f"{sensor}: detected")
        ax.plot(force, [r["measured"] for r in rows[1:]], "s--", color=f"C{j}", label=f"{sensor}: measured")
        ax.plot([force[0] * 0.6], [1.0 - rows[0]["detected"]], "x", color=f"C{j}", markersize=9,
                label=f"{sensor}: no press, in_contact False")
    ax.set_xscale("log")
    ax.set_xlabel("press force [N] (x at the left: frames without a press)")
    ax.set_ylabel("share of frames")
    ax.set_ylim(0, 1.02)
    ax.axhline(0.95, color="0.7", linestyle=":")
    ax.axhline(0.99, color="0.7", linestyle=":")
    ax.legend(fontsize=7, loc="lower right")
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=180, help="rod poses (a third on the nominal sensor)")
    parser.add_argument("--seed", type=int, default=20)
    parser.add_argument("--out", default="docs/results/benchmarks/no_contact.json")
    args = parser.parse_args()
    t0 = time.perf_counter()
    estimator = TactileEstimator.load()
    report: dict[str, Any] = {"noise": judge_noise(estimator),
                              "board": judge_board(estimator, args.poses, args.seed)}
    report["settings"] = {"false_alarm": FALSE_ALARM, "drift_allowance_ut": DRIFT_ALLOWANCE_UT,
                          "min_likeness": MIN_LIKENESS, "poses": args.poses, "seed": args.seed,
                          "forces_n": list(FORCES_N), "rods": [f"{n} {s:g} mm" for n, s in RODS],
                          "noise_floor_ut": estimator.contact.press_check.noise_ut.tolist()}
    report["seconds"] = time.perf_counter() - t0
    report["machine"] = machine_info()
    out = Path(args.out)
    publish(report, out, markdown)
    out.with_suffix(".md").write_text(markdown(report) + "\n")
    figure(report, out.with_suffix(".png"))
    print(f"wrote {out.with_suffix('.md')} and {out.with_suffix('.png')}")


if __name__ == "__main__":
    main()
