"""``tactile-manip demo``: press the paper's objects and unseen rods on the simulated sensor pair.

Prints, per object, the approach into each pad, the peak field change and the time per press, and
writes one PNG per object (depth image and field) to ``--out``.
"""

from __future__ import annotations

import argparse
import math
import time

DEMO_OBJECTS = (("allen_key", {}), ("letter_r", {}), ("cylinder", {"size_mm": 4.0}),
                ("hex_bar", {"size_mm": 6.0}), ("square_bar", {"size_mm": 3.0}), ("procedural", {"seed": 7}))


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/demo", help="folder for the PNGs (default out/demo)")
    p.add_argument("--force", action="store_true", help="replace the PNGs of an earlier demo in --out")
    p.add_argument("--force-n", type=float, default=10.0, help="press force, N (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed for poses and noise")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from tactile_manip.plots import sample_figure
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.shapes import make_indenter
    from tactile_manip.sim.pair import SensorPair

    from tactile_manip.outputs import check_command_folder, claim_folder

    out = check_command_folder(args.out, "demo", [f"{name}.png" for name, _ in DEMO_OBJECTS], force=args.force)
    rng = np.random.default_rng(args.seed)
    pair = SensorPair()
    claim_folder(out, "demo")
    print(f"{'object':<14}{'gel mm':>8}{'skin mm':>9}{'depth max':>11}{'|dB| max uT':>13}{'ms':>7}")
    for name, kwargs in DEMO_OBJECTS:
        pose = IndenterPose(x_mm=rng.uniform(-2, 2), y_mm=rng.uniform(-2, 2), yaw_rad=rng.uniform(-math.pi, math.pi))
        t0 = time.perf_counter()
        s = pair.press(make_indenter(name, **kwargs), pose, args.force_n, rng).check_within_layer()
        ms = (time.perf_counter() - t0) * 1e3
        print(f"{name:<14}{s.approach_mm:>8.2f}{s.skin_approach_mm:>9.2f}{float(s.depth_mm.max()):>11.2f}"
              f"{float(np.abs(s.field_ut).max()):>13.0f}{ms:>7.0f}")
        sample_figure(s.field_ut, s.depth_mm, title=f"{name}, {args.force_n:.0f} N", path=out / f"{name}.png")
    print(f"wrote {len(DEMO_OBJECTS)} figures to {out}/")
    return 0
