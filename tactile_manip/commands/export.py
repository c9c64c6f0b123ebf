"""``tactile-manip export``: convert a source to another tool's format, or a trained checkpoint to ONNX.

``tactile-manip export SOURCE --format lerobot|rrd|mcap --out OUT [--force]`` converts a trial run folder, a
recording or a pair log (:mod:`tactile_manip.interop.export`: the output appears whole or not at all; a
damaged source gives what is intact and the command lists what it skipped). ``--force`` replaces only an earlier
export of the same format: never the source, a path inside it or a folder holding it, nor anything else.

``tactile-manip export --checkpoint RUN/best.pt --out m.onnx`` writes a checkpoint as ONNX (prior + decoder)
with its metadata; for an angle head (``kind = "angle_head"``), ``--attach-to MODEL.onnx`` writes a copy of that
pose model with the head inside (:mod:`tactile_manip.learning.angle_export`). The parity check runs the ONNX file on onnxruntime against torch on the same inputs (real
readings from ``--data`` when given) and refuses to keep a file that disagrees. ``--out`` and ``--card`` must not
be one of the inputs; ``--force`` replaces only an ONNX model of tactile_manip.
"""

from __future__ import annotations

import argparse
import json
import math


CHECKPOINT_ONLY = ("data", "metrics", "pixel_mm", "card", "history", "table", "latency", "attach_to",
                   "image_position_weight")


def share(text: str) -> float:
    """A number in [0, 1] (argparse type)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a share from 0 to 1, got {text!r}")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Both jobs' options, each job's in its own group of ``--help`` (``export-model`` takes the second alone)."""
    from tactile_manip.interop.export import WRITERS

    p.add_argument("source", nargs="?", default=None,
                   help="trial run folder, recording (.tmrec) or pair log to convert (with --format)")
    p.add_argument("--out", required=True,
                   help="output: the dataset folder (lerobot), the .rrd / .mcap file, or the .onnx file")
    p.add_argument("--force", action="store_true",
                   help="replace an earlier output of export at --out (and --card); never the source, nor a file or "
                        "folder export did not write")
    data = p.add_argument_group("converting a trial run, recording or pair log (SOURCE)")
    data.add_argument("--format", choices=sorted(WRITERS), default=None,
                      help="lerobot (a LeRobotDataset v3.0 folder), rrd (Rerun) or mcap")
    data.add_argument("--ros2", action="store_true", help="with --format mcap: a rosbag2-compatible profile")
    data.add_argument("--depth", nargs="?", const="models/supermag.onnx", default=None, metavar="MODEL",
                      help="include each frame's reconstructed depth from MODEL (default models/supermag.onnx; or "
                           "bilinear, bicubic)")
    add_model_arguments(p.add_argument_group("writing a trained model as ONNX (also `tactile-manip export-model`)"),
                        required=False)


def add_model_arguments(g, *, required: bool) -> None:
    """The options of a model export (``--checkpoint`` and what goes with it) on ``g``, a parser or a group."""
    g.add_argument("--checkpoint", required=required, default=None,
                   help="training checkpoint (RUN/best.pt) to write as ONNX: an image model, a contact model, or an "
                        "angle head (with --attach-to)")
    g.add_argument("--attach-to", default=None, metavar="MODEL",
                   help="with an angle head's checkpoint: the pose model (.onnx) to copy to --out with the head inside")
    g.add_argument("--head-symmetries", type=int, choices=(1, 8), default=8,
                   help="with --attach-to: read each reading in the board's 8 symmetric copies and average their "
                        "axes (default), or once (1)")
    g.add_argument("--image-position-weight", type=share, default=None, metavar="W",
                   help="contact models: the reconstructed image's share in the position that TactileEstimator "
                        "gives with this model (0-1; benchmarks/contact_position_fusion.py chooses it on "
                        "validation presses); default: the contact model's position alone")
    g.add_argument("--data", default=None, nargs="+", action="extend",
                   help="the training dataset(s), as given to train: real readings for the parity check, pixel size "
                        "and provenance")
    g.add_argument("--metrics", default=None, help="results.json of `tactile-manip evaluate` to store inside")
    g.add_argument("--pixel-mm", type=float, default=None, help="output pixel size (default: from --data or 0.1)")
    g.add_argument("--card", default=None, help="also write a model card (markdown) here")
    g.add_argument("--history", default=None, help="the run's history.json, for the model card")
    g.add_argument("--table", default=None, help="table.md of `tactile-manip evaluate`, for the model card")
    g.add_argument("--latency", default=None, help="markdown latency table (benchmarks.bench_model), for the card")


def run(args: argparse.Namespace) -> int:
    if args.source is not None:
        return _export_source(args)
    if args.checkpoint is None:
        raise ValueError("give SOURCE with --format (lerobot, rrd, mcap), or --checkpoint to write a model as ONNX")
    for name in ("format", "depth", "ros2"):
        if getattr(args, name) not in (None, False):
            raise ValueError(f"--{name} converts a SOURCE (a trial run, recording or pair log); with --checkpoint "
                             "leave it out")
    return _export_checkpoint(args)


def _export_source(args: argparse.Namespace) -> int:
    import sys

    from tactile_manip.interop.export import export_source

    if args.checkpoint is not None:
        raise ValueError("give either SOURCE (a trial run, recording or pair log) or --checkpoint, not both")
    if args.format is None:
        raise ValueError("SOURCE needs --format: lerobot, rrd or mcap")
    given = [f"--{n.replace('_', '-')}" for n in CHECKPOINT_ONLY if getattr(args, n) is not None]
    if given:
        raise ValueError(f"{', '.join(given)}: only for --checkpoint (model export), not for SOURCE")
    if args.ros2 and args.format != "mcap":
        raise ValueError("--ros2 is an option of --format mcap")
    result = export_source(args.source, args.out, fmt=args.format, force=args.force, ros2=args.ros2,
                           depth_model=args.depth, progress=lambda line: print(f"export: {line}", file=sys.stderr))
    for line in result.source.skipped:
        print(f"export: skipped: {line}", file=sys.stderr)
    src = result.source
    print(f"wrote {result.out} ({args.format}): {len(src.episodes)} episodes, {src.frames} frames from {src.kind} "
          f"{src.path}" + (f"; {len(src.skipped)} damaged or missing parts skipped (listed above)" if src.skipped
                            else ""))
    return 0


def _export_checkpoint(args: argparse.Namespace) -> int:
    from tactile_manip.learning.import_check import require_torch

    require_torch()
    from tactile_manip.extras import require
    from tactile_manip.learning.export import export_onnx
    from tactile_manip.data import load_datasets
    from tactile_manip.outputs import check_output_file

    require("onnx", "export")
    require("onnxruntime", "export's parity check")
    _check_model_outputs(args)
    kind = _checkpoint_kind(args.checkpoint)
    if args.image_position_weight is not None and kind != "contact":
        raise ValueError(f"--image-position-weight is for a contact model's checkpoint; {args.checkpoint} is a "
                         f"{kind} checkpoint")
    if kind == "angle_head":
        return _attach_angle_head(args)
    if args.attach_to is not None:
        raise ValueError(f"--attach-to is for an angle head's checkpoint; {args.checkpoint} is a {kind} checkpoint")
    if kind == "contact":
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
        write_model_card(args.card, meta, history, name=Path(args.out).stem, table_md=table, machine=_cpu_name(),
                         commands=_commands(args), latency=latency)
        print(f"wrote {args.card}")
    return 0


def _check_model_outputs(args: argparse.Namespace) -> None:
    """Refuse an --out or --card that is one of the command's inputs, and an existing --out that is not an ONNX
    model of tactile_manip (with or without --force): --force replaces only what export wrote."""
    from pathlib import Path

    from tactile_manip.outputs import OutputPathError, check_apart, check_output_file

    files = ("attach_to", "metrics", "history", "table", "latency")
    inputs = [("the --checkpoint", args.checkpoint), *(("the --data", path) for path in args.data or ()),
              *((f"the --{name.replace('_', '-')}", getattr(args, name)) for name in files if getattr(args, name))]
    check_apart(args.out, inputs)
    if args.card:
        check_apart(args.card, [*inputs, ("the --out", args.out)], option="--card")
    out = Path(args.out)
    if out.is_file():
        why = _not_our_model(out)
        if why is not None:
            raise OutputPathError(f"{out} is not an ONNX model written by tactile-manip export ({why}); refusing "
                                  "to replace it: choose another --out or remove it yourself")
    check_output_file(out, force=args.force)


def _not_our_model(path) -> str | None:
    """Why the file ``path`` is not an ONNX model of tactile_manip (its producer, or our metadata), or None."""
    import onnx

    try:
        proto = onnx.load(str(path), load_external_data=False)
    except Exception:  # noqa: BLE001 - protobuf and onnx fail in their own ways on what is not a model
        return "it does not parse as an ONNX model"
    keys = [p.key for p in proto.metadata_props]
    if proto.producer_name == "tactile_manip" or any(k.split(".")[0] == "tactile_manip" for k in keys):
        return None
    return f"its producer is {proto.producer_name or 'unnamed'} and it holds no tactile_manip metadata"


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


def _attach_angle_head(args: argparse.Namespace) -> int:
    """Copy --attach-to to --out with the angle head inside; --data gives real readings to check it on."""
    import numpy as np

    from tactile_manip.learning.angle_export import attach_angle_head
    from tactile_manip.data import load_dataset

    if args.attach_to is None:
        raise ValueError(f"{args.checkpoint} is an angle head: give the pose model to attach it to with --attach-to "
                         "MODEL.onnx (e.g. experiments/model_variants/supermag_robust.onnx)")
    given = [f"--{n.replace('_', '-')}" for n in ("metrics", "pixel_mm", "card", "history", "table", "latency")
             if getattr(args, n) is not None]
    if given:
        raise ValueError(f"{', '.join(given)}: not for an angle head, whose validation figures travel in its record")
    readings = None
    if args.data:  # datasets with and without images: each is read alone
        readings = np.concatenate([d.readings[d.indices("val")][:64] for d in map(load_dataset, args.data)])
    record = attach_angle_head(args.checkpoint, args.attach_to, args.out, check_readings=readings,
                               symmetries=args.head_symmetries == 8)
    val = record["validation"]
    copies = "its 8 symmetric copies" if record["symmetries"] == 8 else "1 copy (no symmetric copies)"
    print(f"wrote {args.out}: {args.attach_to} with an angle head of {record['parameters']:,} parameters reading "
          f"{copies} "
          f"(validation {val.get('val_within_5', float('nan')):.1%} within 5 deg), ONNX vs torch max |diff| "
          f"{record['parity_max_abs']:.2e}")
    return 0


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
        data = load_datasets(args.data, images=False)
        windows = dataset_windows(data, payload["input"]["context"])[data.indices("test")]
    metrics = json.loads(open(args.metrics).read()) if args.metrics else {}
    meta = export_contact_onnx(args.checkpoint, args.out, metrics=metrics, check_windows=windows,
                               image_position_weight=args.image_position_weight)
    targets = ", ".join(f"{n} [{u}]" for n, u in zip(meta["targets"]["names"], meta["targets"]["units"]))
    print(f"wrote {args.out}: contact model, {meta['parameters']:,} parameters, targets {targets}, "
          f"{meta['context']['frames']} frame(s) of context, ONNX vs torch max |diff| "
          f"{meta['parity_max_abs']:.2e} target spreads")
    return 0
