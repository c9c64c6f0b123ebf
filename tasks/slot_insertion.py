"""A second task on the tactile pose: put a grasped rod into a slot at a commanded angle and position.

The rod is grasped at a random in-hand angle and offset (as in the reorientation trials). The estimator's
angle AND contact centroid are used: the hand turns the rod parallel to the slot about the pad normal through
the contact, then translates it so the rod's axis passes through the slot's centre. A placement succeeds when
the true rod is within --angle-tolerance-deg of the slot's axis and its axis within the slot's clearance of
the slot's centre. Each presentation is run once per method on the same seed.

Run: python tasks/slot_insertion.py [--trials 60] [--out runs/tasks/slot_insertion]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from tactile_manip.behaviours.place import Slot, place_in_slot
from tactile_manip.robot.frames import hand_T_pad
from tactile_manip.trials.runner import SimulatedCell, build_estimators, draw_presentation
from tactile_manip.trials.scene import load_scene
from tactile_manip.trials.stats import wilson_interval

HERE = Path(__file__).resolve().parent


def draw_slot(base_T_pad: np.ndarray, seed: int, clearance_m: float) -> Slot:
    """A slot in the pad plane, 4-6 cm beyond the pad centre along -pad y, at a random angle."""
    rng = np.random.default_rng([seed, 1])
    angle = rng.uniform(-math.pi / 2, math.pi / 2)
    axis = base_T_pad[:3, :3] @ np.array([math.cos(angle), math.sin(angle), 0.0])
    centre_pad = np.array([rng.uniform(-0.01, 0.01), -rng.uniform(0.04, 0.06), 0.0, 1.0])
    return Slot(centre_base_m=(base_T_pad @ centre_pad)[:3], axis_base=axis, clearance_m=clearance_m)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=60)
    parser.add_argument("--clearance-mm", type=float, default=1.0, help="slot clearance on each side, mm")
    parser.add_argument("--angle-tolerance-deg", type=float, default=5.0)
    parser.add_argument("--out", default="runs/tasks/slot_insertion")
    args = parser.parse_args()

    scene_path = HERE / "slot_insertion.toml"
    scene = dataclasses.replace(load_scene(scene_path), trials=args.trials)
    estimators = build_estimators(scene, scene_path)
    cell = SimulatedCell(scene)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tol_rad, clearance_m = math.radians(args.angle_tolerance_deg), args.clearance_mm * 1e-3
    rows: dict[str, list[dict]] = {name: [] for name in estimators}
    with cell.connected(), (out / "placements.jsonl").open("w") as log:
        for i in range(scene.trials):
            p = draw_presentation(scene, i)
            for name, estimator in estimators.items():
                with cell.presented(p) as (obj, truth):
                    base_T_pad = cell.arm.state().base_T_hand @ hand_T_pad()  # mid-plane of the fingers
                    slot = draw_slot(base_T_pad, p.seed, clearance_m)
                    r = place_in_slot(cell.arm, cell.gripper, cell.sensor, estimator, slot,
                                      object_width_m=obj.width_m, config=scene.behaviour, truth=truth)
                row = {"trial": i, "seed": p.seed, "method": name, "object": obj.name, "outcome": r.outcome,
                       "angle_error_deg": None if r.angle_error_rad is None else math.degrees(r.angle_error_rad),
                       "lateral_error_mm": None if r.lateral_error_m is None else r.lateral_error_m * 1e3,
                       "success": r.succeeded(tol_rad, clearance_m), "detail": r.detail}
                rows[name].append(row)
                log.write(json.dumps(row) + "\n")
                log.flush()
    lines = [f"# Slot insertion ({scene.trials} presentations per method; success: |angle| <= "
             f"{args.angle_tolerance_deg:g} deg and lateral <= {args.clearance_mm:g} mm)", "",
             "| method | success | Wilson 95 % CI | median abs angle (deg) | median lateral (mm) | p95 lateral (mm) |",
             "|---|---|---|---|---|---|"]
    for name, rs in rows.items():
        k = sum(r["success"] for r in rs)
        lo, hi = wilson_interval(k, len(rs))
        ang = [abs(r["angle_error_deg"]) for r in rs if r["angle_error_deg"] is not None]
        lat = [r["lateral_error_mm"] for r in rs if r["lateral_error_mm"] is not None]
        stat = (lambda v, q: f"{np.percentile(v, q):.2f}" if v else "-")
        lines.append(f"| {name} | {k}/{len(rs)} | {lo:.1%} - {hi:.1%} | {stat(ang, 50)} | {stat(lat, 50)} | "
                     f"{stat(lat, 95)} |")
    text = "\n".join(lines) + "\n"
    (out / "summary.md").write_text(text)
    print(text, end="")


if __name__ == "__main__":
    main()
