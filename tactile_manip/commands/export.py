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
    p.add_argument("--data", default=None, help="the training dataset: real readings for the parity check, "
                                                 "pixel size and provenance")
    p.add_argument("--metrics", default=None, help="results.json of `tactile-manip evaluate` to store inside")
    p.add_argument("--pixel-mm", type=float, default=None, help="output pixel size (default: from --data or 0.1)")


def run(args: argparse.Namespace) -> int:
    from tactile_manip.learning.import_check import require_torch

    require_torch()
    from tactile_manip.learning.export import export_onnx
    from tactile_manip.sim.dataset_io import load_dataset

    readings, pixel_mm, extra = None, args.pixel_mm or 0.1, {}
    if args.data:
        data = load_dataset(args.data)
        readings = data.field_ut[data.indices("val")]
        pixel_mm = args.pixel_mm or float(data.metadata.get("pixel_mm", 0.1))
        extra["training_data"] = {"path": str(args.data), "fingerprint": data.fingerprint(), "pairs": len(data),
                                  "objects": data.object_names.tolist(),
                                  "code_version": data.metadata.get("code_version")}
    metrics = json.loads(open(args.metrics).read()) if args.metrics else {}
    meta = export_onnx(args.checkpoint, args.out, pixel_mm=pixel_mm, metrics=metrics, extra=extra,
                       check_readings=readings)
    print(f"wrote {args.out}: {meta['parameters']:,} inference parameters, preset {meta['preset']}, "
          f"ONNX vs torch max |diff| {meta['parity_max_abs_mm']:.2e} mm")
    return 0
