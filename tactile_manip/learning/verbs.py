"""What the model kinds' verbs share (:mod:`tactile_manip.learning.kinds`): the checks ``tactile-manip train``
makes on its run folder and options before any work starts, each a one-line error."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tactile_manip.learning.kinds import TrainRequest

RUN_FILES = ("checkpoint.pt", "best.pt")  # what a run folder holds that a new run would replace


def check_run_folder(request: TrainRequest) -> None:
    """Refuse, before any work, an OUT that cannot be written or whose run would be replaced unasked."""
    from tactile_manip.outputs import check_report_folder

    check_report_folder(request.out, RUN_FILES, force=request.resume or request.force,
                        hint="pass --resume to continue it, --force to start over (replacing it), or give a new --out")


def small_net_config(request: TrainRequest, what: str, load: Callable[[str], Any]) -> Any:
    """The config of a small network (``load(path)``), with the command line's overrides, once the CVAE-only
    flags are refused, the run folder checked and every dataset found (each a one-line error)."""
    from tactile_manip.data import check_dataset_file
    from tactile_manip.errors import ConfigError

    given = [f for f, v in (("--resume", request.resume), ("--init", request.init), ("--device", request.device),
                            ("--max-minutes", request.max_minutes)) if v]
    if given:
        raise ConfigError(f"{', '.join(given)}: not for {what}, which trains in minutes on the CPU")
    check_run_folder(request)
    for path in request.data:
        check_dataset_file(path)
    changes = {k: v for k, v in (("epochs", request.epochs), ("seed", request.seed), ("threads", request.threads))
               if v is not None}
    return dataclasses.replace(load(request.config), **changes)
