"""``tactile-manip export``: write a trained checkpoint as ONNX (prior + decoder) with its metadata.

The parity check runs the ONNX file on onnxruntime against torch on the same inputs (real readings from
``--data`` when given) and refuses to keep a file that disagrees.
"""

from __future__ import annotations

import argparse
import json


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", required=True, help="training checkpoint (RUN/best.pt)")
    p.add_argument("--out", required=True, help="output .onnx")
    p.add_argument("--force", action="store_true", help="replace an existing --out (and --card)")
    p.add_argument("--data", default=None, nargs="+", action="extend",
                   help="the training dataset(s), as given to train: real readings for the parity check, pixel size "
                        "and provenance")
    p.add_argument("--metrics", default=None, help="results.json of `tactile-manip evaluate` to store inside")
    p.add_argument("--pixel-mm", type=float, default=None, help="output pixel size (default: from --data or 0.1)")
    p.add_argument("--card", default=None, help="also write a model card (markdown) here")
    p.add_argument("--history", default=None, help="the run's history.json, for the model card")
    p.add_argument("--table", default=None, help="table.md of `tactile-manip evaluate`, for the model card")
    p.add_argument("--latency", default=None, help="markdown latency table (benchmarks.bench_model), for the card")


def run(args: argparse.Namespace) -> int:
    from tactile_manip.learning.import_check import require_torch

    require_torch()
    from tactile_manip.extras import require
    from tactile_manip.learning.export import export_onnx
    from tactile_manip.data import load_datasets
    from tactile_manip.outputs import check_output_file

    require("onnx", "export")
    require("onnxruntime", "export's parity check")
    check_output_file(args.out, force=args.force)
    if _checkpoint_kind(args.checkpoint) == "contact":
        return _export_contact(args)
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
                       check_readings=readings)
    print(f"wrote {args.out}: {meta['parameters']:,} inference parameters, preset {meta['preset']}, "
          f"ONNX vs torch max |diff| {meta['parity_max_abs_mm']:.2e} mm")
    if args.card:
        from pathlib import Path

        from tactile_manip.learning.card import write_model_card

        history = args.history or str(Path(args.checkpoint).with_name("history.json"))
        table = Path(args.table).read_text() if args.table else ""
        latency = Path(args.latency).read_text() if args.latency else ""
        write_model_card(args.card, meta, history, table_md=table, machine=_cpu_name(),
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


def _checkpoint_kind(path: str) -> str:
    """"contact" for a contact-model checkpoint, else "cvae" (read_checkpoint names a bad file)."""
    from tactile_manip.learning.checkpoint import read_checkpoint

    return str(read_checkpoint(path).get("kind", "cvae"))


def _export_contact(args: argparse.Namespace) -> int:
    """Export a contact model (tactile_manip.learning.contact_export); --data gives real windows to check."""
    from tactile_manip.learning.contact_export import export_contact_onnx, load_contact_checkpoint
    from tactile_manip.learning.contact_train import dataset_windows
    from tactile_manip.data import load_datasets

    if args.card or args.pixel_mm is not None:
        raise ValueError("--card and --pixel-mm are for image models; a contact model keeps its validation "
                         "figures in its metadata")
    windows = None
    if args.data:
        _, payload = load_contact_checkpoint(args.checkpoint)
        data = load_datasets(args.data)
        windows = dataset_windows(data, payload["input"]["context"])[data.indices("test")]
    metrics = json.loads(open(args.metrics).read()) if args.metrics else {}
    meta = export_contact_onnx(args.checkpoint, args.out, metrics=metrics, check_windows=windows)
    targets = ", ".join(f"{n} [{u}]" for n, u in zip(meta["targets"]["names"], meta["targets"]["units"]))
    print(f"wrote {args.out}: contact model, {meta['parameters']:,} parameters, targets {targets}, "
          f"{meta['context']['frames']} frame(s) of context, ONNX vs torch max |diff| "
          f"{meta['parity_max_abs']:.2e} target spreads")
    return 0
