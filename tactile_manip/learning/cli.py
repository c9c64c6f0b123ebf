"""What the model kinds' verbs share (:mod:`tactile_manip.learning.kinds`): the checks ``tactile-manip train``
makes on its run folder and options before any work starts, each a one-line error."""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Callable
from typing import Any

RUN_FILES = ("checkpoint.pt", "best.pt")  # what a run folder holds that a new run would replace


def check_run_folder(args: argparse.Namespace) -> None:
    """Refuse, before any work, an OUT that cannot be written or whose run would be replaced unasked."""
    from tactile_manip.outputs import check_report_folder

    check_report_folder(args.out, RUN_FILES, force=args.resume or args.force,
                        hint="pass --resume to continue it, --force to start over (replacing it), or give a new --out")


def small_net_config(args: argparse.Namespace, what: str, load: Callable[[str], Any]) -> Any:
    """The config of a small network (``load(path)``), with the command line's overrides, once the CVAE-only
    flags are refused, the run folder checked and every dataset found (each a one-line error)."""
    from tactile_manip.data import check_dataset_file
    from tactile_manip.errors import ConfigError

    given = [f for f, v in (("--resume", args.resume), ("--init", args.init), ("--device", args.device),
                            ("--max-minutes", args.max_minutes)) if v]
    if given:
        raise ConfigError(f"{', '.join(given)}: not for {what}, which trains in minutes on the CPU")
    check_run_folder(args)
    for path in args.data:
        check_dataset_file(path)
    changes = {k: v for k, v in (("epochs", args.epochs), ("seed", args.seed), ("threads", args.threads))
               if v is not None}
    return dataclasses.replace(load(args.config), **changes)
