"""Hand-scale perception: 1, 2, 4, 8 and 16 pads through one estimator, per stage, against the angle error.

    python -m benchmarks.bench_pads                       # the shipped model, 240 unseen-rod readings, 3 passes
    python -m benchmarks.bench_pads --readings 96 --repeats 2 --out /tmp/pads.json

Every pad reads another simulated press of the six unseen rods (random in-hand angle, +-2 mm offset, 10-11 N,
chip noise). For each pad count, on one thread, in interleaved calls so a busy machine slows every row alike
(the calls without an image in turns with each other, then those that decode images in turns with each other,
so that a large decode does not leave the light calls a cold cache):

- ``angle``: ``estimate_many`` of the pads' readings, the angles only (the head's route decodes no image);
- ``angle + centroids``: the same call, then every pad's centroid read (the images decoded in one batched run);
- ``image route``: an estimator with ``angle_source = "image"``, the paper's route (every image decoded and
  post-processed: the cost of the whole pipeline before the head), and the same with each image decoded once
  (``image_symmetry="none"``, the runtime default; the model file's ``"rotations"`` averages four passes);
- ``angle + force``: a ``TactileEstimator`` of the same pose estimator and the shipped contact model, its
  ``estimate_many`` (angles and contact states, each in one batched run; no position read);
- per pad, the stages of the ``angle`` call (the head's batched run, the rest) and of the decode.

The estimates of every call of the first pass are checked against the single-pad ``estimate`` of each reading
(angle, confidence, centroid and area equal); the angle error of each route is measured on every reading.
Prints a markdown table and writes it beside the JSON (default ``docs/results/benchmarks/pads.json`` and ``.md``).
It measures; it asserts nothing but the equality.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one thread, as the table says
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402
from benchmarks.bench_pose import PERIOD_MS, rod_readings  # noqa: E402
from tactile_manip.perception import TactilePoseEstimator, load_reconstructor, wrap_axial  # noqa: E402
from tactile_manip.perception.contact import ContactEstimator  # noqa: E402
from tactile_manip.perception.tactile_estimator import TactileEstimator  # noqa: E402
from tactile_manip.shipped import shipped_model  # noqa: E402

PADS = (1, 2, 4, 8, 16)


def measure(model: str, contact: str, readings: int, repeats: int, seed: int) -> dict[str, Any]:
    rec = load_reconstructor(model, threads=1, image_symmetry="stored")  # the default model's four passes per image
    fast = TactilePoseEstimator(rec)
    image = TactilePoseEstimator(rec, angle_source="image")
    once = TactilePoseEstimator(load_reconstructor(model, threads=1, image_symmetry="none"), angle_source="image")
    both = TactileEstimator(fast, ContactEstimator(contact, threads=1))
    fields, angles = rod_readings(readings, seed)
    single = [fast.estimate(f) for f in fields]  # the references every call's estimates must equal
    rows: dict[int, dict[str, list[float]]] = {
        p: {k: [] for k in ("angle", "centroids", "image", "image_once", "head", "decode", "force")} for p in PADS}
    mismatches = 0
    for p in PADS:  # warm-up of every batch size and route
        for start in range(3):
            idx = [(start + k) % readings for k in range(p)]
            [e.centroid_mm for e in fast.estimate_many(fields[idx])]
            image.estimate_many(fields[idx])
            once.estimate_many(fields[idx])
            both.estimate_many(fields[idx])
    for rep in range(repeats):
        # the light calls (no image) interleaved with each other, then the image routes with each other: a
        # decode of many images between two light calls would leave them a cold cache they do not make alone
        for start in range(0, readings, 1):
            for p in PADS:
                batch = fields[_pads(start, p, rep, readings)]
                t0 = time.perf_counter()
                many = fast.estimate_many(batch)
                t1 = time.perf_counter()
                both.estimate_many(batch)
                t2 = time.perf_counter()
                r = rows[p]
                r["angle"].append((t1 - t0) * 1e3)
                r["force"].append((t2 - t1) * 1e3)
                r["head"].append(many[0].timings_s.get("head", 0.0) * 1e3)
        for start in range(0, readings, 1):
            for p in PADS:
                idx = _pads(start, p, rep, readings)
                batch = fields[idx]
                t0 = time.perf_counter()
                many = fast.estimate_many(batch)
                t1 = time.perf_counter()
                for e in many:
                    e.centroid_mm
                t2 = time.perf_counter()
                image.estimate_many(batch)
                t3 = time.perf_counter()
                once.estimate_many(batch)
                t4 = time.perf_counter()
                r = rows[p]
                r["centroids"].append((t2 - t0) * 1e3)
                r["decode"].append((t2 - t1) * 1e3)
                r["image"].append((t3 - t2) * 1e3)
                r["image_once"].append((t4 - t3) * 1e3)
                if rep == 0:
                    mismatches += sum(_key(a) != _key(single[i]) for a, i in zip(many, idx))
    err_head = _errors(single, angles)
    err_image = _errors([image.estimate(f) for f in fields], angles)
    err_once = _errors([once.estimate(f) for f in fields], angles)
    out = {"pads": {}, "equal_to_single_pad": mismatches == 0, "mismatches": mismatches,
           "image_symmetry": rec.image_symmetry,
           "angle_error": {"head": err_head, "image": err_image, "image_once": err_once}}
    for p, r in rows.items():
        out["pads"][str(p)] = {
            **{f"{k}_p50_ms": _pct(v, 50) for k, v in r.items()},
            **{f"{k}_p99_ms": _pct(v, 99) for k, v in r.items()},
            "angle_per_pad_p50_ms": _pct(r["angle"], 50) / p, "decode_per_pad_p50_ms": _pct(r["decode"], 50) / p,
            "calls": len(r["angle"])}
    return out


def _pads(start: int, pads: int, rep: int, readings: int) -> list[int]:
    """The readings of one call: another reading on every pad."""
    return [(start + k * 7 + rep) % readings for k in range(pads)]


def _key(e) -> tuple:
    return (e.angle_rad, e.confidence, e.defined, e.centroid_mm, e.area_mm2, e.source)


def _errors(estimates, angles: np.ndarray) -> dict[str, float]:
    err = np.array([abs(math.degrees(wrap_axial(e.angle_rad - a))) if e.defined else 90.0
                    for e, a in zip(estimates, angles)])
    return {"median_deg": float(np.median(err)), "p95_deg": float(np.percentile(err, 95)),
            "within_5deg": float((err <= 5.0).mean()), "readings": int(err.size)}


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q))


def markdown(report: dict[str, Any]) -> str:
    m, res = report["machine"], report["results"]
    errors = res["angle_error"]
    symmetry = res.get("image_symmetry", "none")
    lines = [f"Pads through one `TactilePoseEstimator` (`estimate_many`), one thread, {report['readings']} unseen-rod "
             f"readings x {report['repeats']} passes; {m['cpu_model']}, {m['usable_cores']} cores, load average "
             f"{m.get('load_average')}; sensor period {PERIOD_MS:g} ms; every estimate equal to its single-pad "
             f"estimate: {res['equal_to_single_pad']}; the model's images averaged over: {symmetry}", "",
             "| pads | angle p50 / p99 ms | per pad p50 ms | head's run p50 ms | angle + force p50 / p99 ms | "
             "angle + centroids p50 / p99 ms | image route p50 / p99 ms | image route, one pass p50 / p99 ms |",
             "|---" * 8 + "|"]
    for p, r in res["pads"].items():
        lines.append(f"| {p} | {r['angle_p50_ms']:.2f} / {r['angle_p99_ms']:.2f} | {r['angle_per_pad_p50_ms']:.3f} | "
                     f"{r['head_p50_ms']:.2f} | {r['force_p50_ms']:.2f} / {r['force_p99_ms']:.2f} | "
                     f"{r['centroids_p50_ms']:.2f} / {r['centroids_p99_ms']:.2f} | "
                     f"{r['image_p50_ms']:.2f} / {r['image_p99_ms']:.2f} | "
                     f"{r['image_once_p50_ms']:.2f} / {r['image_once_p99_ms']:.2f} |")
    lines += ["", "| route | angle error median deg | p95 deg | within 5 deg |", "|---|---|---|---|"]
    for key, name in (("head", "head (the default; images deferred)"), ("image", "image (the paper's route)"),
                      ("image_once", "image, one pass")):
        e = errors[key]
        lines.append(f"| {name} | {e['median_deg']:.2f} | {e['p95_deg']:.2f} | {e['within_5deg']:.1%} |")
    lines += ["", "angle: the call alone; angle + force: `TactileEstimator.estimate_many` with the shipped contact "
              "model (angles and contact states, no position read); these two are timed in turns with each other. "
              "angle + centroids: the call, then every pad's centroid read (the pads' images decoded in one batched "
              "run); image route: every image decoded and post-processed; one pass: the same with the model loaded "
              "with `image_symmetry=\"none\"`; these three are timed in turns with each other, after the first two."]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=str(shipped_model()))
    parser.add_argument("--contact", default=str(shipped_model("contact")), help="contact model of the same board")
    parser.add_argument("--readings", type=int, default=240)
    parser.add_argument("--repeats", type=int, default=3, help="passes over the readings")
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--out", default="docs/results/benchmarks/pads.json")
    args = parser.parse_args()
    if args.readings < max(PADS) or args.repeats < 1:
        parser.error(f"--readings must be >= {max(PADS)} and --repeats >= 1")
    results = measure(args.model, args.contact, args.readings, args.repeats, args.seed)
    model = os.path.relpath(args.model) if os.path.isabs(args.model) else args.model
    contact = os.path.relpath(args.contact) if os.path.isabs(args.contact) else args.contact
    report = {"machine": machine_info(), "model": model, "contact": contact, "readings": args.readings,
              "repeats": args.repeats,
              "seed": args.seed, "results": results}
    publish(report, args.out, markdown)
    Path(args.out).with_suffix(".md").write_text(markdown(report) + "\n")  # the table beside the JSON


if __name__ == "__main__":
    main()
