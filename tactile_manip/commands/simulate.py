"""``tactile-manip simulate``: generate a dataset from a config: readings, depth images (unless the config
says ``images = false``) and contact targets (centre of pressure, depth, force, contact flag).

``tactile-manip simulate --board NAME|FILE --presses N --out D.npz`` instead presses a probe tip on any board
whose file describes its magnetic body and layer (:mod:`tactile_manip.sim.board_dataset`): a dataset of labelled
presses as a probe rig records them (targets x, y, depth, force), for ``train --config
configs/train/contact.toml``. A board without them (``generic:N``) is refused in one line."""

from __future__ import annotations

import argparse
import os

from tactile_manip.progress import progress_bar

MIN_PROBE_PRESSES = 3  # --board: one press each for the train, val and test splits
SIMULATED_WHAT = "dataset written by tactile-manip simulate"  # the only file --force replaces


def _simulated(path) -> bool:
    from tactile_manip.data.io import dataset_source

    return (dataset_source(path) or "").startswith(("tactile-manip simulate", "tactile_manip.sim."))

DEFAULT_CONFIG = "configs/dataset/supermag.toml"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", default=DEFAULT_CONFIG, help=f"dataset TOML (default: {DEFAULT_CONFIG})")
    p.add_argument("--out", required=True,
                   help="output .npz file (.npz is appended when missing); with --shard-size, a folder")
    p.add_argument("--shard-size", type=int, default=None, metavar="N",
                   help="write OUT as a folder of shards of at most N samples plus manifest.json, each shard "
                        "written as it completes (docs/data.md, Sharded datasets)")
    p.add_argument("--workers", type=int, default=0, help="worker processes (0 = all cores)")
    p.add_argument("--scale", type=float, default=1.0,
                   help="multiply every object count (e.g. 0.05 for a quick small dataset)")
    p.add_argument("--seed", type=int, default=None, help="override the config's base seed")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.add_argument("--quiet", action="store_true",
                   help="no progress display (off a terminal it is a line per stage anyway)")
    p.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                   help="run the presses as Ray tasks: 'local' (the default without ADDRESS: a private instance on "
                        "this machine with --workers CPUs), 'auto' (the cluster this machine joined) or HOST:PORT; "
                        "the result equals the local run's, and a restarted run keeps its finished blocks "
                        "(extra 'ray')")
    p.add_argument("--block-size", type=int, default=None,
                   help="presses per Ray task (default 32); only with --ray")
    probe = p.add_argument_group("probe presses on any board (instead of --config)")
    probe.add_argument("--board", default=None, metavar="NAME|FILE",
                       help="press a probe on this board (a shipped board, or a board file with [body] and [layer]): "
                            "labelled presses as a probe rig records them, without images")
    probe.add_argument("--presses", type=int, default=2000, help="with --board: how many presses (default 2000)")
    probe.add_argument("--tip", choices=("sphere", "flat"), default="sphere", help="with --board: the probe's tip")
    probe.add_argument("--tip-diameter-mm", type=float, default=6.0, help="with --board: its diameter, mm (6)")
    probe.add_argument("--max-force-n", type=float, default=15.0,
                       help="with --board: forces are drawn log-uniformly from 0.5 N to this (15)")


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from tactile_manip.outputs import check_output_file
    from tactile_manip.sim.dataset import generate, load_dataset_config
    from tactile_manip.data import SPLITS, dataset_path, save_dataset

    if args.board is not None:
        return _simulate_board(args)
    if args.shard_size is not None and args.shard_size < 1:
        raise ValueError(f"--shard-size must be >= 1, got {args.shard_size}")
    out = (_check_shard_folder(args.out, force=args.force) if args.shard_size else  # checked before the work
           check_output_file(dataset_path(args.out), force=args.force, ours=_simulated, what=SIMULATED_WHAT))
    if args.workers < 0:
        raise ValueError(f"--workers must be >= 0, got {args.workers}")
    if not 0 < args.scale <= 100:
        raise ValueError(f"--scale must be in (0, 100], got {args.scale}")
    cfg = load_dataset_config(args.config)
    if args.scale != 1.0:
        cfg = cfg.scaled(args.scale)
    if args.seed is not None:
        cfg = dataclasses.replace(cfg, seed=args.seed)
    if args.shard_size and args.ray is None:
        return _simulate_shards(args, cfg, out)
    total = sum(o.count for o in cfg.objects)
    if args.ray is not None:
        data = _generate_on_ray(args, cfg, out, total)
        if args.shard_size:  # the blocks come back to this machine; the dataset is written as shards
            return _save_ray_shards(args, cfg, out, data)
    else:
        if args.block_size is not None:
            raise ValueError("--block-size applies to --ray runs only")
        workers = args.workers or os.cpu_count() or 1
        with progress_bar(total=total, unit="pair", desc=f"simulating ({workers} workers)",
                      quiet=args.quiet) as bar:
            data = generate(cfg, workers=workers, progress=bar.update)
    path = save_dataset(out, data)
    if args.ray is not None:
        from tactile_manip.cluster.blocks import remove_blocks

        remove_blocks(out)
    counts = ", ".join(f"{s} {len(data.indices(s))}" for s in SPLITS)
    seconds = data.provenance["generation_seconds"]
    what = "pairs" if data.has_images else "presses (no images)"
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB): {len(data)} {what} ({counts}) in {seconds:.1f} s, "
          f"{len(data) / seconds:.1f} presses/s; targets {', '.join(data.target_names)}")
    for note in _physics_notes(data, thickness_mm=cfg.sensor_board().layer.thickness_mm):
        print(f"note: {note}")
    return 0


def _generate_on_ray(args: argparse.Namespace, cfg, out, total: int):
    from tactile_manip.cluster.connect import check_address, preflight
    from tactile_manip.cluster.simulate import DEFAULT_BLOCK_SIZE, block_bounds, generate_on_ray

    address = check_address(args.ray)
    block_size = DEFAULT_BLOCK_SIZE if args.block_size is None else args.block_size
    block_bounds(total, block_size)  # a bad --block-size fails here, before Ray starts
    if address is not None and args.workers:
        raise ValueError("--workers sets the CPUs of a private local Ray instance; a cluster (--ray ADDRESS) "
                         "uses all of its own")
    preflight(address)  # an unreachable cluster fails here, before the progress bar
    where = "a local Ray instance" if address is None else f"Ray at {address}"
    with progress_bar(total=total, unit="pair", desc=f"simulating on {where}",
                      quiet=args.quiet) as bar:
        return generate_on_ray(cfg, out, address=address, num_cpus=args.workers or None, block_size=block_size,
                               progress=bar.update)


def _physics_notes(data, *, thickness_mm: float) -> list[str]:
    """Samples the config made outside the model's range: empty presses, and presses that bottom out."""
    import numpy as np

    notes = []
    empty = int(np.count_nonzero(~data.extra("contact")))
    if empty:
        notes.append(f"{empty} of {len(data)} presses do not touch the pad (empty: noise and drift only)")
    deepest = np.maximum(data.extra("approach_mm"), data.extra("skin_approach_mm"))
    bottomed = int(np.count_nonzero(deepest >= thickness_mm))
    if bottomed:
        notes.append(f"{bottomed} of {len(data)} presses bottom out (approach >= the {thickness_mm:g} mm layer, "
                     f"up to {deepest.max():.3g} mm): the elastic layer model does not hold there; lower "
                     "poses.force_n or use blunter objects")
    return notes


def _simulate_board(args: argparse.Namespace) -> int:
    """``--board``: probe presses on any simulatable board, checked before any press."""
    from tactile_manip.boards import load_board
    from tactile_manip.data import SPLITS, dataset_path, save_dataset
    from tactile_manip.outputs import check_output_file
    from tactile_manip.sim.board_dataset import ProbePlan, probe_press_dataset

    other = [flag for flag, given in (("--config", args.config != DEFAULT_CONFIG), ("--ray", args.ray is not None),
                                      ("--shard-size", args.shard_size is not None), ("--scale", args.scale != 1.0),
                                      ("--block-size", args.block_size is not None)) if given]
    if other:
        options = " and ".join(other)
        raise ValueError(f"--board presses a probe on one board, in this process; {options} "
                         f"{'is an option' if len(other) == 1 else 'are options'} of a dataset config (--config), "
                         "not of --board")
    if not MIN_PROBE_PRESSES <= args.presses <= 1_000_000:  # checked before any press
        raise ValueError(f"--presses must be from {MIN_PROBE_PRESSES} to 1000000 (a press each for validation and "
                         f"test, and one to train on), got {args.presses}")
    out = check_output_file(dataset_path(args.out), force=args.force, ours=_simulated, what=SIMULATED_WHAT)
    board = load_board(args.board)
    board.require_simulation()
    plan = ProbePlan(tip=args.tip, tip_diameter_mm=args.tip_diameter_mm, max_force_n=args.max_force_n)
    with progress_bar(total=args.presses, unit="press", desc=f"pressing {board.name}",
                      quiet=args.quiet) as bar:
        data = probe_press_dataset(board, args.presses, plan=plan, seed=0 if args.seed is None else args.seed,
                                   progress=bar.update)
    path = save_dataset(out, data)
    counts = ", ".join(f"{s} {len(data.indices(s))}" for s in SPLITS)
    print(f"wrote {path}: {len(data)} probe presses of board {board.name} ({counts}), "
          f"{data.provenance['generation_seconds']:.1f} s; targets {', '.join(data.target_names)}")
    return 0


def _check_shard_folder(path: str, *, force: bool):
    """The shard folder to write, after checking nothing is there (unless ``force``) and its parent is writable."""
    from pathlib import Path

    from tactile_manip.outputs import OutputPathError, check_writable_parent

    out = Path(path)
    if (out.exists() or out.is_symlink()) and not force:
        raise OutputPathError(f"{out} exists; pass --force to replace it (once the new dataset is complete)")
    check_writable_parent(out)
    return out


def _save_ray_shards(args: argparse.Namespace, cfg, out, data) -> int:
    from tactile_manip.cluster.blocks import remove_blocks
    from tactile_manip.data import ShardedDataset, save_sharded

    path = save_sharded(out, data, shard_size=args.shard_size, force=args.force)
    remove_blocks(out)
    return _report_shards(ShardedDataset(path), path, cfg)


def _simulate_shards(args: argparse.Namespace, cfg, out) -> int:
    """Simulate into a shard folder, each shard written as its samples finish (the dataset is never whole in
    memory)."""
    from tactile_manip.data import ShardedDataset
    from tactile_manip.sim.dataset import generate_shards

    workers = args.workers or os.cpu_count() or 1
    with progress_bar(total=sum(o.count for o in cfg.objects), unit="pair",
                      desc=f"simulating ({workers} workers)", quiet=args.quiet) as bar:
        path = generate_shards(cfg, out, shard_size=args.shard_size, workers=workers, progress=bar.update,
                               force=args.force)
    return _report_shards(ShardedDataset(path), path, cfg)


def _report_shards(data, path, cfg) -> int:
    counts = ", ".join(f"{s} {n}" for s, n in data.splits.items())
    seconds = data.provenance["generation_seconds"]
    size_mb = sum(f.stat().st_size for f in path.iterdir()) / 1e6
    print(f"wrote {path}/ ({data.shard_count} shards, {size_mb:.1f} MB): {len(data)} presses ({counts}) in "
          f"{seconds:.1f} s, {len(data) / seconds:.1f} presses/s; fingerprint {data.fingerprint()}")
    for note in _physics_notes(data, thickness_mm=cfg.sensor_board().layer.thickness_mm):
        print(f"note: {note}")
    return 0
