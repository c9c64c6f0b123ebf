"""``tactile-manip train``: train a SuperMag CVAE on a paired dataset (torch; `pip install -e ".[train]"`).

A config with ``kind = "contact"`` (configs/train/contact.toml) trains the contact network on labelled
presses instead (:mod:`tactile_manip.learning.contact_train`), and ``kind = "angle_head"``
(configs/train/angle_head.toml) the pose model's angle head (:mod:`tactile_manip.learning.angle_train`).

Start it with ``torchrun --nproc_per_node N -m tactile_manip train ...`` to train data-parallel.
"""

from __future__ import annotations

import argparse
from typing import Any


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", required=True,
                   help="training TOML: its `kind` says what it trains (e.g. configs/train/robust_b48.toml, the "
                        "default model's image recipe; configs/train/angle_head.toml, its angle head; "
                        "configs/train/contact.toml, a contact model)")
    p.add_argument("--data", required=True, nargs="+", action="extend",
                   help="paired dataset .npz or shard folder (tactile-manip simulate / collect / import); several "
                        "are trained on as one, each keeping its splits; shard folders are streamed")
    p.add_argument("--out", required=True, help="run folder for checkpoints, history and plots")
    again = p.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    again.add_argument("--force", action="store_true",
                       help="start over in an OUT that holds a run, replacing its best.pt and checkpoint.pt")
    p.add_argument("--init", default=None, metavar="CHECKPOINT",
                   help="fine-tune: start from this checkpoint's weights and input normalisation (e.g. the best.pt "
                        "of a run; configs/train/finetune_robust.toml), with a fresh optimiser and the config's "
                        "schedule")
    p.add_argument("--epochs", type=int, default=None, help="override the config's epochs")
    p.add_argument("--seed", type=int, default=None, help="override the config's seed")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads per process")
    p.add_argument("--device", default=None, help="override the config's device: auto, cpu, cuda or cuda:N")
    p.add_argument("--max-minutes", type=float, default=None,
                   help="override the config's wall-time cap in minutes (0: none)")


def run(args: argparse.Namespace) -> int:
    from tactile_manip.learning.import_check import require_torch

    require_torch()
    kind = _config_kind(args.config)
    if kind == "contact":
        return _run_contact(args)
    if kind == "angle_head":
        return _run_angle_head(args)
    from tqdm import tqdm

    from tactile_manip.learning.train import load_train_config, resolve_device, train, with_overrides
    from tactile_manip.data import check_dataset_file
    from tactile_manip.errors import ConfigError

    _check_run_folder(args)
    for path in args.data:
        check_dataset_file(path)  # before the progress bar: a missing file is one line
    if args.init and args.resume:
        raise ConfigError("--init starts a new run from a checkpoint's weights; --resume continues this run's own "
                          "checkpoint: give one of them")
    cfg = with_overrides(load_train_config(args.config), epochs=args.epochs, seed=args.seed, threads=args.threads,
                         device=args.device, max_minutes=args.max_minutes)
    resolve_device(cfg.device)  # a missing GPU is one line before any progress bar or output folder
    bars = []  # the bar starts once data, model and checkpoint are loaded, so their errors stay one line

    def start(done: int) -> None:
        bars.append(tqdm(total=cfg.epochs, initial=done, unit="epoch", desc=f"training {cfg.preset}"))

    def progress(row: dict) -> None:
        bars[0].update(1)
        bars[0].set_postfix(loss=f"{row['loss']:.0f}", val_psnr=f"{row['val_psnr']:.2f}")

    try:
        summary = train(cfg, args.data, args.out, resume=args.resume, init=args.init, progress=progress,
                        on_start=start)
    finally:
        for bar in bars:
            bar.close()
    if summary:
        print(f"best validation PSNR {summary['best_val_psnr']:.2f} dB at epoch {summary['best_epoch']} "
              f"({summary['epochs_run']} epochs, {summary['train_seconds'] / 60:.1f} min); wrote {args.out}/")
    return 0


def _check_run_folder(args: argparse.Namespace) -> None:
    """Refuse, before any work, an OUT that cannot be written or whose run would be replaced unasked."""
    from tactile_manip.commands import check_report_folder

    check_report_folder(args.out, ("checkpoint.pt", "best.pt"), force=args.resume or args.force,
                        hint="pass --resume to continue it, --force to start over (replacing it), or give a new --out")


def _config_kind(path: str) -> str:
    """The config's ``kind`` ("contact", or "cvae" when absent); an unreadable file is left to the loader."""
    import tomllib
    from pathlib import Path

    try:
        return str(tomllib.loads(Path(path).read_text()).get("kind", "cvae"))
    except (OSError, ValueError):
        return "cvae"


def _small_net_config(args: argparse.Namespace, what: str, load: Any) -> Any:
    """The config of a small network (``load(path)``), with the command line's overrides, once the CVAE-only
    flags are refused, the run folder checked and every dataset found (each a one-line error)."""
    import dataclasses

    from tactile_manip.data import check_dataset_file
    from tactile_manip.errors import ConfigError

    given = [f for f, v in (("--resume", args.resume), ("--init", args.init), ("--device", args.device),
                            ("--max-minutes", args.max_minutes)) if v]
    if given:
        raise ConfigError(f"{', '.join(given)}: not for {what}, which trains in minutes on the CPU")
    _check_run_folder(args)
    for path in args.data:
        check_dataset_file(path)
    changes = {k: v for k, v in (("epochs", args.epochs), ("seed", args.seed), ("threads", args.threads))
               if v is not None}
    return dataclasses.replace(load(args.config), **changes)


def _run_angle_head(args: argparse.Namespace) -> int:
    """Train the pose model's angle head on simulated presses; the CVAE-only flags are refused."""
    from tqdm import tqdm

    from tactile_manip.learning.angle_train import load_angle_config, train_angle_head

    cfg = _small_net_config(args, 'an angle head (kind = "angle_head")', load_angle_config)
    bars = []

    def start(total: int) -> None:
        bars.append(tqdm(total=total, unit="epoch", desc="training angle head"))

    def progress(row: dict) -> None:
        bars[0].update(1)
        bars[0].set_postfix(loss=f"{row['loss']:.3f}", val_nll=f"{row['val_nll']:.3f}",
                            within_5=f"{row['val_within_5']:.1%}")

    try:
        summary = train_angle_head(cfg, args.data, args.out, progress=progress, on_start=start)
    finally:
        for bar in bars:
            bar.close()
    val = summary["val"]
    print(f"validation: {val['val_within_5']:.1%} within 5 deg, {val['val_within_2']:.1%} within 2 deg, median "
          f"{val['val_median_deg']:.2f} deg on the axial presses, NLL {val['val_nll']:.3f} "
          f"({summary['val_presses']} presses; best epoch {summary['best_epoch']}; "
          f"{summary['train_seconds'] / 60:.1f} min); wrote {args.out}/best.pt, history.json")
    return 0


def _run_contact(args: argparse.Namespace) -> int:
    """Train the contact network (targets from labelled presses); the CVAE-only flags are refused."""
    from tqdm import tqdm

    from tactile_manip.learning.contact_train import load_contact_config, train_contact

    cfg = _small_net_config(args, 'a contact model (kind = "contact")', load_contact_config)
    bars = []

    def start(total: int) -> None:
        bars.append(tqdm(total=total, unit="epoch", desc=f"training contact x{cfg.members}"))

    def progress(row: dict) -> None:
        bars[0].update(1)
        bars[0].set_postfix(member=row["member"], loss=f"{row['loss']:.3f}", val_rmse=f"{row['val_rmse']:.3f}")

    try:
        summary = train_contact(cfg, args.data, args.out, progress=progress, on_start=start)
    finally:
        for bar in bars:
            bar.close()
    rmse = ", ".join(f"{k} {v:.3g}" for k, v in summary["val_rmse"].items())
    pseudo = summary.get("pseudo_labels")
    if pseudo:
        loo = ", ".join(f"{k} {v:.3g} ({m})" for k, v, m in zip(summary["targets"], pseudo["loo_rmse"],
                                                               pseudo["methods"]))
        print(f"{pseudo['unlabelled']} unlabelled presses labelled from {pseudo['labelled']} on the map of the "
              f"readings; leave-one-out RMSE on the labelled: {loo}")
        rmse += " against those labels"
    print(f"validation RMSE {rmse} ({summary['val_samples']} samples; {summary['train_seconds'] / 60:.1f} min); "
          f"wrote {args.out}/best.pt, history.json")
    return 0
