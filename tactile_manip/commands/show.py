"""``tactile-manip show``: render one sample to PNG, from a dataset or from a fresh simulated press."""

from __future__ import annotations

import argparse
import math


def add_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", help="dataset .npz to read the sample from")
    src.add_argument("--object", help="simulate a press of this object instead (e.g. letter_r)")
    p.add_argument("--index", type=int, default=0, help="sample index in --data (default 0)")
    p.add_argument("--x-mm", type=float, default=0.0, help="press position x, mm (with --object)")
    p.add_argument("--y-mm", type=float, default=0.0, help="press position y, mm (with --object)")
    p.add_argument("--yaw-deg", type=float, default=0.0, help="object yaw, degrees (with --object)")
    p.add_argument("--force-n", type=float, default=10.0, help="press force, N (with --object)")
    p.add_argument("--seed", type=int, default=0, help="noise seed (with --object)")
    p.add_argument("--out", default="sample.png", help="output PNG (default sample.png; .png added without a suffix)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")


def run(args: argparse.Namespace) -> int:
    from tactile_manip.outputs import check_output_file
    from tactile_manip.plots import figure_path, sample_figure

    out = check_output_file(figure_path(args.out), force=args.force)
    if args.data is not None:  # not truthiness: an empty --data is an error, not a simulated press
        field, depth, title, note, how = _from_dataset(args)
    else:
        (field, depth, title, note), how = _from_simulation(args), {}
    sample_figure(field, depth, title=title, path=out, **how)
    if note:
        print(f"note: {note}")
    print(f"wrote {out}")
    return 0


def _from_dataset(args: argparse.Namespace):
    from tactile_manip.checks import check_nonblank
    from tactile_manip.data import load_dataset

    data = load_dataset(check_nonblank("--data", args.data))
    data.require_images(f"show --data {args.data}")
    if not 0 <= args.index < len(data):
        raise ValueError(f"--index must be in [0, {len(data) - 1}], got {args.index}")
    i = args.index
    title = f"{args.data} #{i}: {data.objects([i])[0]} ({data.split[i]})"
    if data.has("pose") and data.has("force_n"):
        x, y, yaw = data.extra("pose")[i, :3]
        title += f" at ({x:.1f}, {y:.1f}) mm, yaw {math.degrees(yaw):.0f} deg, {data.extra('force_n')[i]:.1f} N"
    empty = data.has("contact") and not data.extra("contact")[i]
    note = f"sample {i} is an empty press: the object does not touch the pad" if empty else ""
    how = {"channels": data.channels, "image_unit": data.image.unit, "pixel_mm": data.image.pixel_mm,
           "image_range": (data.image.value_min, data.image.value_max)}
    return data.readings[i], data.image_values([i])[0], title, note, how


def _from_simulation(args: argparse.Namespace):
    import numpy as np

    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.shapes import make_indenter
    from tactile_manip.sim.pair import SensorPair

    pose = IndenterPose(x_mm=args.x_mm, y_mm=args.y_mm, yaw_rad=math.radians(args.yaw_deg))
    pair = SensorPair()
    s = pair.press(make_indenter(args.object), pose, args.force_n, np.random.default_rng(args.seed))
    s.check_within_layer()  # 1e6 N would report a 7254 mm approach into the 2.5 mm layer
    title = (f"{args.object} at ({args.x_mm:.1f}, {args.y_mm:.1f}) mm, yaw {args.yaw_deg:.0f} deg, "
             f"{args.force_n:.1f} N: approach {s.approach_mm:.2f} mm (gel), {s.skin_approach_mm:.2f} mm (skin)")
    note = "" if s.contact else (
        f"{args.object} at ({args.x_mm:g}, {args.y_mm:g}) mm does not touch the {pair.board.layer.size_mm[0]:g} mm "
        "pad (pad centre at (0, 0)): an empty press, noise and drift only")
    return s.field_ut, s.depth_mm, title, note
