"""Simulator benchmark: time per press (by object and by stage) and dataset throughput per worker count.

Run from the repository root (see ``benchmarks/README.md``)::

    python -m benchmarks.bench_sim [--samples N] [--workers 1 2] [--out docs/results/benchmarks/sim.json] [--full]

Prints markdown tables and writes a JSON report with the machine it ran on. It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.sim.contact import solve_contact
from tactile_manip.sim.dataset import DatasetConfig, generate, load_dataset_config
from tactile_manip.sim.objects import Indenter, IndenterPose
from tactile_manip.sim.shapes import make_indenter
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.vbts import dtact_depth

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CONFIG = ROOT / "configs" / "dataset" / "supermag.toml"
DEFAULT_OUT = ROOT / "docs" / "results" / "benchmarks" / "sim.json"
OBJECTS = (("allen_key", {}), ("letter_r", {}), ("cylinder", {"size_mm": 4.0}), ("procedural", {"seed": 7}))
FORCE_N = 10.5      # middle of the dataset's 10-11 N range
OFFSET_MM = 2.0     # presses land within +-2 mm of the pad centre, so every one touches


def _ms(fn: Callable[[], Any]) -> tuple[float, Any]:
    t0 = time.perf_counter()
    out = fn()
    return (time.perf_counter() - t0) * 1e3, out


def _stats(ms: list[float]) -> dict[str, float]:
    a = np.asarray(ms)
    return {"median": float(np.median(a)), "p90": float(np.percentile(a, 90)), "min": float(a.min())}


def _stage_ms(pair: SensorPair, indenter: Indenter, pose: IndenterPose, rng: np.random.Generator
              ) -> dict[str, float]:
    """Time the three stages of ``SensorPair.press`` in isolation, on the inputs that press would use."""
    p = pair.params
    # The gaps on the contact and image grids, exactly as press() computes them (no public accessor).
    gap_c, gap_i = pair._gaps(indenter, pose)
    pixel_mm = pair.board.layer.size_mm[0] / gap_c.shape[0]

    def solve(modulus_kpa: float):
        return solve_contact(gap_c, force_n=FORCE_N, modulus_mpa=modulus_kpa * 1e-3,
                             thickness_mm=pair.thickness_mm, pixel_mm=pixel_mm,
                             tolerance=p.contact.tolerance, max_iterations=p.contact.max_iterations)

    t_skin, skin = _ms(lambda: solve(p.layer.skin_modulus_kpa))
    t_gel, gel = _ms(lambda: solve(p.layer.vbts_modulus_kpa))
    t_mag, _ = _ms(lambda: pair.skin.field_change_t(skin.pressure_mpa, skin.pixel_mm))
    imprint = np.clip(gel.approach_mm - np.nan_to_num(gap_i, nan=np.inf), 0.0, None)
    t_vbts, _ = _ms(lambda: dtact_depth(imprint, p.vbts, rng))
    return {"contact": t_skin + t_gel, "contact_skin": t_skin, "contact_gel": t_gel, "magnetic": t_mag,
            "vbts": t_vbts, "skin_iterations": skin.iterations, "gel_iterations": gel.iterations}


def bench_presses(samples: int, seed: int) -> list[dict[str, Any]]:
    """Per object: press time with and without VBTS rendering, and the time of each stage."""
    pair = SensorPair()
    rows = []
    for name, kwargs in OBJECTS:
        indenter = make_indenter(name, **kwargs)
        pose_rng = np.random.default_rng([seed, len(rows)])
        poses = [IndenterPose(x_mm=x, y_mm=y, yaw_rad=yaw) for x, y, yaw in
                 pose_rng.uniform([-OFFSET_MM, -OFFSET_MM, -math.pi], [OFFSET_MM, OFFSET_MM, math.pi], (samples, 3))]
        pair.press(indenter, poses[0], FORCE_N, np.random.default_rng(0))  # warm-up: caches, lookup tables
        with_vbts, without_vbts, stages = [], [], []
        for i, pose in enumerate(poses):
            t, s = _ms(lambda: pair.press(indenter, pose, FORCE_N, np.random.default_rng([seed, i])))
            with_vbts.append(t)
            t, _ = _ms(lambda: pair.press(indenter, pose, FORCE_N, np.random.default_rng([seed, i]),
                                          render_depth=False))
            without_vbts.append(t)
            if s.contact:
                st = _stage_ms(pair, indenter, pose, np.random.default_rng([seed, i]))
                st["other"] = with_vbts[-1] - st["contact"] - st["magnetic"] - st["vbts"]  # gaps, chips, copies
                stages.append(st)
        stage_median = {k: float(np.median([s[k] for s in stages])) for k in stages[0]} if stages else {}
        rows.append({"object": name, "kwargs": kwargs, "samples": samples, "with_vbts_ms": _stats(with_vbts),
                     "without_vbts_ms": _stats(without_vbts), "stage_median_ms": stage_median})
    return rows


def bench_generate(config: Path, scale: float, workers: list[int]) -> list[dict[str, Any]]:
    """``generate`` wall time (pool start-up included) on a scaled config, per worker count."""
    full = load_dataset_config(config)
    cfg = full.scaled(scale)
    n, n_full = _pairs(cfg), _pairs(full)
    rows = []
    for w in workers:
        t0 = time.perf_counter()
        generate(cfg, workers=w)
        wall = time.perf_counter() - t0
        rows.append({"workers": w, "scale": scale, "pairs": n, "wall_s": wall, "pairs_per_s": n / wall,
                     "full_pairs": n_full, "projected_full_s": n_full / (n / wall)})
    return rows


def bench_full(config: Path, workers: int) -> dict[str, Any]:
    """Generate the whole dataset of ``config`` once and time it."""
    cfg = load_dataset_config(config)
    t0 = time.perf_counter()
    generate(cfg, workers=workers)
    wall = time.perf_counter() - t0
    return {"workers": workers, "pairs": _pairs(cfg), "wall_s": wall, "pairs_per_s": _pairs(cfg) / wall}


def _pairs(cfg: DatasetConfig) -> int:
    return sum(o.count for o in cfg.objects)


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [f"Machine: {m['cpu_model']}, {m['usable_cores']}/{m['cpu_count']} cores, Python {m['python']}, "
             f"numpy {m['numpy']}, scipy {m['scipy']}, code {m['code_version']}", "",
             f"### One press ({report['settings']['samples']} per object, {FORCE_N} N), ms",
             "| object | press median | press p90 | no VBTS median | no VBTS p90 | contact (2 solves) "
             "| magnetic | VBTS | other (per-press remainder) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in report["presses"]:
        s = r["stage_median_ms"]
        w, wo = r["with_vbts_ms"], r["without_vbts_ms"]
        lines.append(f"| {r['object']} | {w['median']:.1f} | {w['p90']:.1f} | {wo['median']:.1f} | {wo['p90']:.1f} "
                     f"| {s.get('contact', math.nan):.1f} | {s.get('magnetic', math.nan):.1f} "
                     f"| {s.get('vbts', math.nan):.1f} | {s.get('other', math.nan):.1f} |")
    g = report["generate"]
    if g:
        lines += ["", f"### generate (config x{g[0]['scale']:g}: {g[0]['pairs']} pairs; pool start-up included)",
                  f"| workers | wall s | pairs/s | projected {g[0]['full_pairs']} pairs |", "|---|---|---|---|"]
        lines += [f"| {r['workers']} | {r['wall_s']:.1f} | {r['pairs_per_s']:.1f} | "
                  f"{r['projected_full_s'] / 60:.1f} min |" for r in g]
    if report["full"]:
        f = report["full"]
        lines += ["", f"### Full dataset: {f['pairs']} pairs with {f['workers']} workers in {f['wall_s']:.0f} s "
                      f"({f['pairs_per_s']:.1f} pairs/s)"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench_sim", description=__doc__.splitlines()[0])
    p.add_argument("--samples", type=int, default=20, help="presses per object for the per-press timings")
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="worker counts for generate")
    p.add_argument("--scale", type=float, default=0.01, help="scale of the config for the throughput run")
    p.add_argument("--config", type=Path, default=DEFAULT_CONFIG, help="dataset config (default: supermag)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON report path")
    p.add_argument("--seed", type=int, default=0, help="seed for poses and noise")
    p.add_argument("--full", action="store_true", help="also generate the full dataset (max --workers)")
    args = p.parse_args(argv)
    if args.samples < 1 or min(args.workers) < 1 or not 0 < args.scale <= 1:
        p.error("--samples and --workers must be >= 1 and --scale in (0, 1]")
    report = {"machine": machine_info(),
              "settings": {"samples": args.samples, "workers": args.workers, "scale": args.scale,
                           "config": str(args.config), "seed": args.seed, "force_n": FORCE_N,
                           "offset_mm": OFFSET_MM},
              "presses": bench_presses(args.samples, args.seed),
              "generate": bench_generate(args.config, args.scale, args.workers),
              "full": bench_full(args.config, max(args.workers)) if args.full else None}
    publish(report, args.out, markdown)
    return 0


if __name__ == "__main__":
    sys.exit(main())
