"""What the model kinds' verbs share (:mod:`tactile_manip.learning.kinds`): the checks ``tactile-manip train``
makes on its run folder and options before any work starts, each a one-line error."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tactile_manip.learning.kinds import ExportRequest, TrainRequest

RUN_FILES = ("checkpoint.pt", "best.pt")  # what a run folder holds that a new run would replace


def check_data_of_checkpoint(request: ExportRequest, cells: list[int], board: dict | None, data) -> None:
    """Refuse, before the export's work, ``--data`` of another reading grid or board than the checkpoint's
    (``cells``: its (rows, cols, channels); ``board``: its board record, None where unknown)."""
    from tactile_manip.boards.identity import check_same_board, record_of_provenance
    from tactile_manip.errors import DatasetError

    if list(data.readings.shape[1:]) != [int(c) for c in cells]:
        raise DatasetError(f"--data {' '.join(request.data)} holds ({', '.join(map(str, data.readings.shape[1:]))}) "
                           f"readings, but the checkpoint {request.checkpoint} reads ({', '.join(map(str, cells))}): "
                           "give the data it was trained on")
    check_same_board(f"the checkpoint {request.checkpoint}", board, f"--data {' '.join(request.data)}",
                     record_of_provenance(data.provenance))


def start_run(request: TrainRequest, *, total: int, desc: str, initial: int = 0):
    """The run begins (its data loaded and checked): ``request.out`` becomes train's folder, and the progress
    display of ``total`` epochs starts."""
    from tactile_manip.outputs import claim_folder
    from tactile_manip.progress import progress_bar

    claim_folder(request.out, "train")
    return progress_bar(total=total, initial=initial, unit="epoch", desc=desc, quiet=request.quiet)


def check_run_folder(request: TrainRequest) -> None:
    """Refuse, before any work, an OUT that cannot be written, that train did not create (it may hold a user's
    files), or whose run would be replaced unasked."""
    from tactile_manip.outputs import check_command_folder

    check_command_folder(request.out, "train", RUN_FILES, force=request.resume or request.force,
                        hint="pass --resume to continue it, --force to start over (replacing it), or give a new --out")


def small_net_config(request: TrainRequest, what: str, load: Callable[[str], Any], *, takes_prior: bool = False
                     ) -> Any:
    """The config of a small network (``load(path)``), with the command line's overrides, once the CVAE-only
    flags (and ``--prior``, unless it ``takes_prior``) are refused, the run folder checked and every dataset found
    (each a one-line error)."""
    from tactile_manip.data import check_dataset_file
    from tactile_manip.errors import ConfigError

    given = [f for f, v in (("--resume", request.resume), ("--init", request.init), ("--device", request.device),
                            ("--max-minutes", request.max_minutes),
                            ("--prior", None if takes_prior else request.prior)) if v]
    if given:
        raise ConfigError(f"{', '.join(given)}: not for {what}, which trains in minutes on the CPU")
    check_run_folder(request)
    for path in request.data:
        check_dataset_file(path)
    changes = {k: v for k, v in (("epochs", request.epochs), ("seed", request.seed), ("threads", request.threads))
               if v is not None}
    return dataclasses.replace(load(request.config), **changes)
