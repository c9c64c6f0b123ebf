"""The CVAE's verbs (kind ``"cvae"``, :mod:`tactile_manip.learning.kinds`): ``tactile-manip train`` on its config
and ``export --checkpoint`` / ``export-model`` of its checkpoint, with the model card."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tactile_manip.learning.kinds import ExportRequest, TrainRequest


def run_train(request: TrainRequest) -> int:
    """Train the CVAE (:mod:`.train`) with a progress bar; print the best validation PSNR."""
    from tactile_manip.data import check_dataset_file
    from tactile_manip.errors import ConfigError
    from tactile_manip.learning.cvae.train import load_train_config, resolve_device, train, with_overrides
    from tactile_manip.learning.verbs import check_run_folder, start_run

    if request.prior:
        raise ConfigError("--prior: for a contact model that labels its presses from a twin "
                          "(configs/train/contact_twin.toml), not for the image model")
    check_run_folder(request)
    for path in request.data:
        check_dataset_file(path)  # before the progress bar: a missing file is one line
    if request.init and request.resume:
        raise ConfigError("--init starts a new run from a checkpoint's weights; --resume continues this run's own "
                          "checkpoint: give one of them")
    cfg = with_overrides(load_train_config(request.config), epochs=request.epochs, seed=request.seed,
                         threads=request.threads,
                         device=request.device, max_minutes=request.max_minutes)
    resolve_device(cfg.device)  # a missing GPU is one line before any progress bar or output folder
    bars = []  # the bar starts once data, model and checkpoint are loaded, so their errors stay one line

    def start(done: int) -> None:
        bars.append(start_run(request, total=cfg.epochs, initial=done, desc=f"training {cfg.preset}"))

    def progress(row: dict) -> None:
        bars[0].update(1)
        bars[0].set_postfix(loss=f"{row['loss']:.0f}", val_psnr=f"{row['val_psnr']:.2f}")

    try:
        summary = train(cfg, list(request.data), request.out, resume=request.resume, init=request.init,
                        progress=progress, on_start=start)
    finally:
        for bar in bars:
            bar.close()
    if summary:
        print(f"best validation PSNR {summary['best_val_psnr']:.2f} dB at epoch {summary['best_epoch']} "
              f"({summary['epochs_run']} epochs, {summary['train_seconds'] / 60:.1f} min); wrote {request.out}/")
    return 0


def run_export(request: ExportRequest) -> int:
    """Write the checkpoint as ONNX (:mod:`.export`); ``data`` gives real readings, pixel size and provenance,
    --card a model card."""
    from tactile_manip.data import load_datasets
    from tactile_manip.boards.identity import record_of_name
    from tactile_manip.learning.cvae.export import export_onnx, load_checkpoint
    from tactile_manip.learning.verbs import check_data_of_checkpoint
    from tactile_manip.outputs import check_output_file

    if request.card:
        check_output_file(request.card, force=request.force)
    readings, pixel_mm, extra = None, request.pixel_mm or 0.1, {}
    if request.data:
        data = load_datasets(list(request.data))
        data.require_images("export of an image model with --data")
        model, _, _ = load_checkpoint(request.checkpoint)
        grid = (model.cfg.taxel_rows, model.cfg.taxel_cols)
        check_data_of_checkpoint(request, [*grid, data.readings.shape[-1]],
                                 record_of_name("supermag-4x4" if grid == (4, 4) else ""), data)
        readings = data.readings[data.indices("val")]
        pixel_mm = request.pixel_mm or data.image.pixel_mm or 0.1
        trained_on = sorted(set(data.objects(data.indices("train")).tolist()))
        extra["training_data"] = {"path": " ".join(request.data), "fingerprint": data.fingerprint(), "pairs": len(data),
                                  "objects": sorted(set(data.objects().tolist())),
                                  "objects_with_train_split": trained_on, "source": data.provenance.get("source"),
                                  "image": data.image.to_dict(),
                                  "code_version": data.provenance.get("code_version")}
    metrics = json.loads(open(request.metrics).read()) if request.metrics else {}
    meta = export_onnx(request.checkpoint, request.out, pixel_mm=pixel_mm, metrics=metrics, extra=extra,
                       check_readings=readings, image_symmetry=request.image_symmetry or "none")
    print(f"wrote {request.out}: {meta['parameters']:,} inference parameters, preset {meta['preset']}, "
          f"ONNX vs torch max |diff| {meta['parity_max_abs_mm']:.2e} mm")
    if request.card:
        from pathlib import Path

        from tactile_manip.learning.card import write_model_card

        history = request.history or str(Path(request.checkpoint).with_name("history.json"))
        table = Path(request.table).read_text() if request.table else ""
        latency = Path(request.latency).read_text() if request.latency else ""
        write_model_card(request.card, meta, history, name=Path(request.out).stem, table_md=table, machine=_cpu_name(),
                         commands=_commands(request), latency=latency)
        print(f"wrote {request.card}")
    return 0


def _cpu_name() -> str:
    import os
    from pathlib import Path

    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return f"{line.split(':', 1)[1].strip()} ({os.cpu_count()} cores)"
    except OSError:
        pass
    return f"{os.cpu_count()} cores"


def _commands(request: ExportRequest) -> list[str]:
    from pathlib import Path

    run = Path(request.checkpoint).parent
    data = [Path(d) for d in (request.data or ["data/supermag.npz"])]
    files = " ".join(map(str, data))
    return [*(f"tactile-manip simulate --config configs/dataset/{d.stem}.toml --out {d}" for d in data),
            f"tactile-manip train --config configs/train/{run.name}.toml --data {files} --out {run}",
            f"tactile-manip export --checkpoint {request.checkpoint} --out {request.out} --data {files} --force"]
