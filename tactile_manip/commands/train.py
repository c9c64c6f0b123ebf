"""``tactile-manip train``: train a SuperMag CVAE on a paired dataset (torch; `pip install -e ".[train]"`).

A config with ``kind = "contact"`` (configs/train/contact.toml) trains the contact network on labelled
presses instead (:mod:`tactile_manip.learning.contact.train`), and ``kind = "angle_head"``
(configs/train/angle_head.toml) the pose model's angle head (:mod:`tactile_manip.learning.angle_head.train`).
The config's kind is looked up in :mod:`tactile_manip.learning.kinds`, whose entry runs the training (an unknown
kind is refused with the known ones).

Start it with ``torchrun --nproc_per_node N -m tactile_manip train ...`` to train data-parallel.
"""

from __future__ import annotations

import argparse


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
    p.add_argument("--prior", default=None, metavar="TWIN.npz",
                   help="contact models with unlabelled = \"twin\" (configs/train/contact_twin.toml): simulated "
                        "presses of the pad's twin (tactile-manip simulate --board fitted.toml), which label the "
                        "unlabelled presses")
    p.add_argument("--quiet", action="store_true",
                   help="no progress display (off a terminal it is a line per stage anyway); the summary is printed")


def run(args: argparse.Namespace) -> int:
    from tactile_manip.learning.import_check import require_torch
    from tactile_manip.learning.kinds import TrainRequest, kind_of_config

    kind = kind_of_config(args.config)  # an unknown kind is one line naming the file and the known kinds
    require_torch()
    return kind.run_train(TrainRequest(
        config=args.config, data=tuple(args.data), out=args.out, resume=args.resume, force=args.force, init=args.init,
        epochs=args.epochs, seed=args.seed, threads=args.threads, device=args.device, max_minutes=args.max_minutes,
        quiet=args.quiet, prior=args.prior))
