"""The contact network's verbs (kind ``"contact"``, :mod:`tactile_manip.learning.kinds`): ``tactile-manip train``
on its config and ``export --checkpoint`` / ``export-model`` of its checkpoint."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tactile_manip.learning.kinds import ExportRequest, TrainRequest


def run_train(request: TrainRequest) -> int:
    """Train the contact network (:mod:`.train`; targets from labelled presses); the CVAE-only flags are
    refused."""
    import functools
    import time

    from tactile_manip.learning.contact.train import load_contact_config, train_contact
    from tactile_manip.learning.verbs import small_net_config, start_run
    from tactile_manip.progress import progress_bar

    began = time.perf_counter()
    cfg = small_net_config(request, 'a contact model (kind = "contact")', load_contact_config, takes_prior=True)
    bars = []

    def start(total: int) -> None:
        bars.append(start_run(request, total=total, desc=f"training contact x{cfg.members}"))

    def progress(row: dict) -> None:
        bars[0].update(1)
        bars[0].set_postfix(member=row["member"], loss=f"{row['loss']:.3f}", val_rmse=f"{row['val_rmse']:.3f}")

    try:
        summary = train_contact(cfg, list(request.data), request.out, progress=progress, on_start=start,
                                stages=functools.partial(progress_bar, quiet=request.quiet), prior=request.prior)
    finally:
        for bar in bars:
            bar.close()
    rmse = ", ".join(f"{k} {v:.3g}" for k, v in summary["val_rmse"].items())
    pseudo = summary.get("pseudo_labels")
    took = f"network {_minutes(summary['train_seconds'])}"
    if pseudo:
        loo = ", ".join(f"{k} {v:.3g} ({m})" for k, v, m in zip(summary["targets"], pseudo["loo_rmse"],
                                                               pseudo["methods"]))
        source = f" and the twin {request.prior}" if request.prior else ""
        print(f"{pseudo['unlabelled']} unlabelled presses labelled from {pseudo['labelled']}{source} in "
              f"{_minutes(pseudo['seconds'])}; leave-one-out RMSE of each target's fit on the labelled: {loo}")
        rmse += " against those labels"
        took = f"labelling {_minutes(pseudo['seconds'])}, {took}"
    # the whole command's wall time beside its parts: the network's time alone is not what the command took
    print(f"validation RMSE {rmse} ({summary['val_samples']} samples); {took}, train in all "
          f"{_minutes(time.perf_counter() - began)}; wrote {request.out}/best.pt, history.json")
    return 0


def _minutes(seconds: float) -> str:
    """A duration as people read it: seconds below two minutes, minutes above."""
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"


def run_export(request: ExportRequest) -> int:
    """Export a contact model (:mod:`.export`); ``data`` gives real windows to check it on."""
    from tactile_manip.data import load_datasets
    from tactile_manip.learning.contact.export import export_contact_onnx, load_contact_checkpoint
    from tactile_manip.boards.identity import record_of_name
    from tactile_manip.learning.contact.train import dataset_windows
    from tactile_manip.learning.verbs import check_data_of_checkpoint

    if request.card or request.pixel_mm is not None:
        raise ValueError("--card and --pixel-mm are for image models; a contact model keeps its validation "
                         "figures in its metadata")
    windows = None
    if request.data:
        _, payload = load_contact_checkpoint(request.checkpoint)
        data = load_datasets(list(request.data), images=False)
        check_data_of_checkpoint(request, payload["input"]["cells"],
                                 payload["input"].get("board") or record_of_name(payload["input"]["layout"]), data)
        windows = dataset_windows(data, payload["input"]["context"])[data.indices("test")]
    metrics = json.loads(open(request.metrics).read()) if request.metrics else {}
    meta = export_contact_onnx(request.checkpoint, request.out, metrics=metrics, check_windows=windows,
                               image_position_weight=request.image_position_weight)
    targets = ", ".join(f"{n} [{u}]" for n, u in zip(meta["targets"]["names"], meta["targets"]["units"]))
    print(f"wrote {request.out}: contact model, {meta['parameters']:,} parameters, targets {targets}, "
          f"{meta['context']['frames']} frame(s) of context, ONNX vs torch max |diff| "
          f"{meta['parity_max_abs']:.2e} (relative to each target's spread)")
    return 0
