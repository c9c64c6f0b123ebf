"""The fast pose pipeline against the reference on the shipped model's reconstructions of the test split.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.check_pose_parity        # data/supermag.npz, shipped model
    python -m benchmarks.check_pose_parity --model runs/x/model.onnx --data other.npz

Reconstructs every test-split reading (unseen objects) with the model, then runs
:func:`~tactile_manip.perception.pose.angle_from_image` (on its C kernel, when built, and on its numpy path) and
the full-image float64 :func:`~tactile_manip.evaluation.pose_reference.reference_angle_from_image` on each
image, interleaved, and prints per path the largest differences (angle in degrees, confidence, centroid, area),
the number of images whose defined flag or reason differ, and the post-processing time (p50 / p99, one thread). Writes
docs/results/benchmarks/pose_parity.json. The acceptance bar is a largest angle difference of
0.05 deg with no flag changed; the script reports, it does not assert.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: the filter's small products on one thread

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402
from tactile_manip.perception import load_reconstructor, pose_kernel, wrap_axial  # noqa: E402
from tactile_manip.perception.pose import DEFAULT_THRESHOLD_MM, angle_from_image  # noqa: E402
from tactile_manip.evaluation.pose_reference import reference_angle_from_image  # noqa: E402
from tactile_manip.data import load_dataset  # noqa: E402

ANGLE_BAR_DEG = 0.05
BOX_GROUPS = ((0.0, 0.25), (0.25, 0.75), (0.75, 1.01))  # the contact's bounding box, as a share of the image


def box_share(img: np.ndarray, threshold_mm: float = DEFAULT_THRESHOLD_MM) -> float:
    """Share of the image inside the bounding box of the pixels above the threshold (0: no contact): the
    fast pipeline's labelling and filter work on that box, so its cost grows with it."""
    mask = np.asarray(img) > threshold_mm
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return 0.0
    return (rows[-1] - rows[0] + 1) * (cols[-1] - cols[0] + 1) / mask.size


def compare(images: np.ndarray, pixel_mm: float) -> dict[str, Any]:
    """Both pipelines on every image (N, H, W): largest differences, flag changes and timings."""
    diffs = {"angle_deg": 0.0, "confidence": 0.0, "centroid_mm": 0.0, "area_mm2": 0.0}
    flag_changes, defined, fast_ms, ref_ms = 0, 0, [], []
    boxes = np.array([box_share(img) for img in images])
    for img in images:
        t0 = time.perf_counter()
        new = angle_from_image(img, pixel_mm=pixel_mm)
        t1 = time.perf_counter()
        ref = reference_angle_from_image(img, pixel_mm=pixel_mm)
        t2 = time.perf_counter()
        fast_ms.append((t1 - t0) * 1e3)
        ref_ms.append((t2 - t1) * 1e3)
        if new.defined != ref.defined or new.reason.split(" (")[0] != ref.reason.split(" (")[0]:
            flag_changes += 1
            continue
        defined += new.defined
        diffs["angle_deg"] = max(diffs["angle_deg"], abs(math.degrees(wrap_axial(new.angle_rad - ref.angle_rad))))
        diffs["confidence"] = max(diffs["confidence"], abs(new.confidence - ref.confidence))
        diffs["centroid_mm"] = max(diffs["centroid_mm"], float(np.abs(np.subtract(new.centroid_mm,
                                                                                   ref.centroid_mm)).max()))
        diffs["area_mm2"] = max(diffs["area_mm2"], abs(new.area_mm2 - ref.area_mm2))
    pct = lambda ms, q: float(np.percentile(ms, q))  # noqa: E731
    return {"images": len(images), "defined": int(defined), "flag_changes": flag_changes, "max_diff": diffs,
            "within_bar": diffs["angle_deg"] <= ANGLE_BAR_DEG and flag_changes == 0,
            "fast_p50_ms": pct(fast_ms, 50), "fast_p99_ms": pct(fast_ms, 99),
            "reference_p50_ms": pct(ref_ms, 50), "reference_p99_ms": pct(ref_ms, 99),
            "by_box": [{"box_share": [lo, min(hi, 1.0)], "images": int(np.count_nonzero(sel)),
                        "fast_p50_ms": pct(np.asarray(fast_ms)[sel], 50) if sel.any() else None}
                       for lo, hi in BOX_GROUPS for sel in [(boxes >= lo) & (boxes < hi)]]}


def markdown(report: dict[str, Any]) -> str:
    results = report["results"]
    first = next(iter(results.values()))
    lines = [f"Pose parity on {report['source']} ({first['images']} images, {first['defined']} with a defined "
             f"angle), model {report['model']}", "",
             "| path of angle_from_image | largest angle diff deg | confidence | centroid mm | area mm2 | "
             "flag/reason changes | within bar |", "|---|---|---|---|---|---|---|"]
    for path, r in results.items():
        d = r["max_diff"]
        lines.append(f"| {path} | {d['angle_deg']:.2e} | {d['confidence']:.2e} | {d['centroid_mm']:.2e} | "
                     f"{d['area_mm2']:.3f} | {r['flag_changes']} | {'yes' if r['within_bar'] else 'NO'} "
                     f"(bar {ANGLE_BAR_DEG} deg) |")
    lines += ["", "| post-processing | p50 ms | p99 ms |", "|---|---|---|",
              *[f"| angle_from_image, {path} | {r['fast_p50_ms']:.3f} | {r['fast_p99_ms']:.3f} |"
                for path, r in results.items()],
              f"| reference (full image, float64) | {first['reference_p50_ms']:.3f} | "
              f"{first['reference_p99_ms']:.3f} |", "",
              "| contact's bounding box (share of the image) | images | "
              + " | ".join(f"{path} p50 ms" for path in results) + " |", "|---|---|" + "---|" * len(results)]
    for k, g in enumerate(first["by_box"]):
        cells = ["-" if r["by_box"][k]["fast_p50_ms"] is None else f"{r['by_box'][k]['fast_p50_ms']:.3f}"
                 for r in results.values()]
        lines.append(f"| {g['box_share'][0]:.0%}-{g['box_share'][1]:.0%} | {g['images']} | " + " | ".join(cells)
                     + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="experiments/model_variants/supermag_fast.onnx")
    parser.add_argument("--data", default="data/supermag.npz")
    parser.add_argument("--split", default="test")
    parser.add_argument("--out", default="docs/results/benchmarks/pose_parity.json")
    args = parser.parse_args()
    data = load_dataset(args.data)
    rec = load_reconstructor(args.model, threads=1)
    images = rec.reconstruct_batch(data.field_ut[data.indices(args.split)])
    results = {}
    if pose_kernel.available():
        results["C kernel"] = compare(images, rec.pixel_mm)
    with pose_kernel.numpy_path():
        results["numpy"] = compare(images, rec.pixel_mm)
    report = {"machine": machine_info(), "model": args.model, "source": f"{args.data} {args.split} split",
              "results": results}
    publish(report, args.out, markdown)


if __name__ == "__main__":
    main()
