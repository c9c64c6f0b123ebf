"""The CVAE's verbs (kind ``"cvae"``, :mod:`tactile_manip.learning.kinds`): ``tactile-manip train`` on its config
and ``export --checkpoint`` / ``export-model`` of its checkpoint, with the model card."""

from __future__ import annotations

import argparse
import json


def run_train(args: argparse.Namespace) -> int:
    """Train the CVAE (:mod:`.train`) with a progress bar; print the best validation PSNR."""
    from tqdm import tqdm

    from tactile_manip.data import check_dataset_file
    from tactile_manip.errors import ConfigError
    from tactile_manip.learning.cli import check_run_folder
    from tactile_manip.learning.cvae.train import load_train_config, resolve_device, train, with_overrides

    check_run_folder(args)
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


def run_export(args: argparse.Namespace) -> int:
    """Write the checkpoint as ONNX (:mod:`.export`); --data gives real readings, pixel size and provenance,
    --card a model card."""
    from tactile_manip.data import load_datasets
    from tactile_manip.learning.cvae.export import export_onnx
    from tactile_manip.outputs import check_output_file

    if args.card:
        check_output_file(args.card, force=args.force)
    readings, pixel_mm, extra = None, args.pixel_mm or 0.1, {}
    if args.data:
        data = load_datasets(args.data)
        data.require_images("export of an image model with --data")
        readings = data.readings[data.indices("val")]
        pixel_mm = args.pixel_mm or data.image.pixel_mm or 0.1
        trained_on = sorted(set(data.objects(data.indices("train")).tolist()))
        extra["training_data"] = {"path": " ".join(args.data), "fingerprint": data.fingerprint(), "pairs": len(data),
                                  "objects": sorted(set(data.objects().tolist())),
                                  "objects_with_train_split": trained_on, "source": data.provenance.get("source"),
                                  "image": data.image.to_dict(),
                                  "code_version": data.provenance.get("code_version")}
    metrics = json.loads(open(args.metrics).read()) if args.metrics else {}
    meta = export_onnx(args.checkpoint, args.out, pixel_mm=pixel_mm, metrics=metrics, extra=extra,
                       check_readings=readings, image_symmetry=args.image_symmetry or "none")
    print(f"wrote {args.out}: {meta['parameters']:,} inference parameters, preset {meta['preset']}, "
          f"ONNX vs torch max |diff| {meta['parity_max_abs_mm']:.2e} mm")
    if args.card:
        from pathlib import Path

        from tactile_manip.learning.card import write_model_card

        history = args.history or str(Path(args.checkpoint).with_name("history.json"))
        table = Path(args.table).read_text() if args.table else ""
        latency = Path(args.latency).read_text() if args.latency else ""
        write_model_card(args.card, meta, history, name=Path(args.out).stem, table_md=table, machine=_cpu_name(),
                         commands=_commands(args), latency=latency)
        print(f"wrote {args.card}")
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


def _commands(args: argparse.Namespace) -> list[str]:
    from pathlib import Path

    run = Path(args.checkpoint).parent
    data = [Path(d) for d in (args.data or ["data/supermag.npz"])]
    files = " ".join(map(str, data))
    return [*(f"tactile-manip simulate --config configs/dataset/{d.stem}.toml --out {d}" for d in data),
            f"tactile-manip train --config configs/train/{run.name}.toml --data {files} --out {run}",
            f"tactile-manip export --checkpoint {args.checkpoint} --out {args.out} --data {files} --force"]
