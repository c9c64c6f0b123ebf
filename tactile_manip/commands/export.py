"""``tactile-manip export``: convert a source to another tool's format, or a trained checkpoint to ONNX.

``tactile-manip export SOURCE --format lerobot|rrd|mcap --out OUT [--force]`` converts a trial run folder, a
recording or a pair log (:mod:`tactile_manip.interop.export`: the output appears whole or not at all; a
damaged source gives what is intact and the command lists what it skipped). ``--force`` replaces only an earlier
export of the same format: never the source, a path inside it or a folder holding it, nor anything else.

``tactile-manip export --checkpoint RUN/best.pt --out m.onnx`` writes a checkpoint as ONNX (prior + decoder)
with its metadata; for an angle head (``kind = "angle_head"``), ``--attach-to MODEL.onnx`` writes a copy of that
pose model with the head inside (:mod:`tactile_manip.learning.angle_head.export`). The checkpoint's kind is looked
up in :mod:`tactile_manip.learning.kinds`, whose entry writes it. The parity check runs the ONNX file on
onnxruntime against torch on the same inputs (real readings from ``--data`` when given) and refuses to keep a file
that disagrees. ``--out`` and ``--card`` must not be one of the inputs; ``--force`` replaces only an ONNX model of
tactile_manip.
"""

from __future__ import annotations

import argparse
import math


CHECKPOINT_ONLY = ("data", "metrics", "pixel_mm", "card", "history", "table", "latency", "attach_to",
                   "image_position_weight", "image_symmetry")
# the model-export options that one kind's checkpoint takes and every other refuses: option -> (its kind, the
# checkpoint it is for, as the refusal names it)
KIND_ONLY_OPTIONS = {"image_position_weight": (("contact",), "a contact model's"),
                     "attach_to": (("angle_head",), "an angle head's"),
                     "image_symmetry": (("cvae", "angle_head"), "an image model's or an angle head's")}


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
    data.add_argument("--depth", nargs="?", const="supermag", default=None, metavar="MODEL",
                      help="include each frame's reconstructed depth from MODEL (default: the shipped supermag "
                           "model, found from any folder; or a .onnx path, bilinear, bicubic)")
    add_model_arguments(p.add_argument_group("writing a trained model as ONNX (also `tactile-manip export-model`)"),
                        required=False)


def add_model_arguments(g, *, required: bool) -> None:
    """The options of a model export (``--checkpoint`` and what goes with it) on ``g``, a parser or a group."""
    from tactile_manip.perception.board_symmetry import IMAGE_SYMMETRIES

    g.add_argument("--checkpoint", required=required, default=None,
                   help="training checkpoint (RUN/best.pt) to write as ONNX: an image model, a contact model, or an "
                        "angle head (with --attach-to)")
    g.add_argument("--attach-to", default=None, metavar="MODEL",
                   help="with an angle head's checkpoint: the pose model (.onnx) to copy to --out with the head inside")
    g.add_argument("--head-symmetries", type=int, choices=(1, 8), default=8,
                   help="with --attach-to: read each reading in the board's 8 symmetric copies and average their "
                        "axes (default), or once (1)")
    g.add_argument("--image-symmetry", choices=IMAGE_SYMMETRIES, default=None,
                   help="image models, and with --attach-to the pose model: average each image over the reading's "
                        "4 quarter turns (rotations; the shipped model) or its 8 symmetric copies (all), at 4 or 8 "
                        "decoder passes per image, or decode it once (none; the default of a new image model; with "
                        "--attach-to: as the pose model says)")
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
    """The checkpoint's kind (:mod:`tactile_manip.learning.kinds`) writes it, once the outputs are checked and the
    options of another kind's checkpoint refused."""
    from tactile_manip.learning.import_check import require_torch

    require_torch()
    from tactile_manip.extras import require
    from tactile_manip.learning.kinds import ExportRequest, kind_of_checkpoint

    require("onnx", "export")
    require("onnxruntime", "export's parity check")
    _check_model_outputs(args)
    kind = kind_of_checkpoint(args.checkpoint)
    for name, (owner, whose) in KIND_ONLY_OPTIONS.items():
        if getattr(args, name) is not None and kind.name not in owner:
            raise ValueError(f"--{name.replace('_', '-')} is for {whose} checkpoint; {args.checkpoint} is a "
                             f"{kind.name} checkpoint")
    return kind.run_export(ExportRequest(
        checkpoint=args.checkpoint, out=args.out, force=args.force, data=tuple(args.data or ()), metrics=args.metrics,
        pixel_mm=args.pixel_mm, card=args.card, history=args.history, table=args.table, latency=args.latency,
        attach_to=args.attach_to, head_symmetries=args.head_symmetries, image_symmetry=args.image_symmetry,
        image_position_weight=args.image_position_weight))


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
