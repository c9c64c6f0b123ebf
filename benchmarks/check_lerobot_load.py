"""Load exported LeRobot datasets with lerobot's own ``LeRobotDataset``, offline, and read every frame back.

    tactile-manip trials --config configs/scenes/reorient_sim.toml --trials 3 --out R
    tactile-manip export R --format lerobot --out DS
    HF_HUB_OFFLINE=1 LEROBOT_PYTHON benchmarks/check_lerobot_load.py DS [DS2 ...]

Run it with a Python that has ``lerobot`` (0.4.x; it needs neither tactile_manip nor its dependencies, only
lerobot, pyarrow and numpy). For each dataset it loads ``LeRobotDataset(repo_id, root=DS)`` with the Hub
offline, checks its episode count, frame count and fps against ``meta/info.json``, reads every frame through
``__getitem__`` and compares each numeric feature with the parquet file read by pyarrow (exact for float32,
int and bool features; ``host_time_s`` to float32, which lerobot's torch transform gives), decodes every image
feature, and loads once more with ``delta_timestamps`` (the past 2 frames of the tactile field) as a policy
would. Prints a table and writes docs/results/benchmarks/lerobot_load.json. Exit status 1 when any check fails.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("HF_HUB_OFFLINE", "1")  # before lerobot: never reach the Hub

import numpy as np  # noqa: E402


def check(root: Path) -> dict[str, Any]:
    """Every check on one dataset folder; ``problems`` lists what failed (empty: it loads and matches)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    info = json.loads((root / "meta" / "info.json").read_text())
    problems: list[str] = []
    t0 = time.perf_counter()
    ds = LeRobotDataset(repo_id=f"local/{root.name}", root=root)
    load_s = time.perf_counter() - t0
    if ds.num_episodes != info["total_episodes"]:
        problems.append(f"episodes {ds.num_episodes} != info {info['total_episodes']}")
    if len(ds) != info["total_frames"]:
        problems.append(f"frames {len(ds)} != info {info['total_frames']}")
    if ds.fps != info["fps"]:
        problems.append(f"fps {ds.fps} != info {info['fps']}")
    table = pa.concat_tables([pq.read_table(p) for p in sorted((root / "data").glob("*/*.parquet"))])
    features = info["features"]
    numeric = [k for k, ft in features.items() if ft["dtype"] not in ("image", "video")]
    images = [k for k, ft in features.items() if ft["dtype"] == "image"]
    columns = {k: table.column(k).to_pylist() for k in numeric}
    row_of = {index: row for row, index in enumerate(columns["index"])}
    t0 = time.perf_counter()
    mismatched: dict[str, int] = {}
    for i in range(len(ds)):
        item = ds[i]
        row = row_of[int(item["index"])]
        for key in numeric:
            got = item[key].numpy()
            want = np.asarray(columns[key][row])
            if key == "host_time_s":
                want = np.float32(want)
            if got.shape != tuple(features[key]["shape"]) and not (got.shape == () and features[key]["shape"] == [1]):
                mismatched[f"{key} shape"] = mismatched.get(f"{key} shape", 0) + 1
            if not np.array_equal(got.astype(np.float64), np.asarray(want, np.float64), equal_nan=True):
                mismatched[key] = mismatched.get(key, 0) + 1
        for key in images:
            h, w, c = features[key]["shape"]
            if tuple(item[key].shape) != (c, h, w):
                mismatched[f"{key} shape"] = mismatched.get(f"{key} shape", 0) + 1
        if not isinstance(item["task"], str) or not item["task"]:
            mismatched["task"] = mismatched.get("task", 0) + 1
    read_s = time.perf_counter() - t0
    problems += [f"{key}: {n} frames differ" for key, n in mismatched.items()]
    dt = 1.0 / info["fps"]
    windowed = LeRobotDataset(repo_id=f"local/{root.name}", root=root,
                              delta_timestamps={"observation.tactile.field": [-2 * dt, -dt, 0.0]})
    last = windowed[len(windowed) - 1]
    if tuple(last["observation.tactile.field"].shape) != (3, features["observation.tactile.field"]["shape"][0]):
        problems.append("delta_timestamps: the windowed tactile field has the wrong shape")
    return {"dataset": str(root), "episodes": ds.num_episodes, "frames": len(ds), "fps": ds.fps,
            "features": sorted(features), "tactile_shape": features["observation.tactile.field"]["shape"],
            "frames_read": len(ds), "load_s": round(load_s, 3), "read_s": round(read_s, 3),
            "tasks": len(ds.meta.tasks), "problems": problems}


def markdown(report: dict[str, Any]) -> str:
    lines = [f"lerobot {report['lerobot']} on Python {report['python']}, HF_HUB_OFFLINE={report['offline']}", "",
             "| dataset | episodes | frames | fps | tactile | frames read | load s | read s | result |",
             "|---|---:|---:|---:|---|---:|---:|---:|---|"]
    for r in report["datasets"]:
        result = "ok" if not r["problems"] else "; ".join(r["problems"])
        lines.append(f"| {Path(r['dataset']).name} | {r['episodes']} | {r['frames']} | {r['fps']} | "
                     f"{r['tactile_shape']} | {r['frames_read']} | {r['load_s']} | {r['read_s']} | {result} |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("datasets", nargs="+", help="dataset folders written by `tactile-manip export --format lerobot`")
    parser.add_argument("--out", default="docs/results/benchmarks/lerobot_load.json", help="JSON report")
    args = parser.parse_args()
    import lerobot

    report = {"lerobot": getattr(lerobot, "__version__", "?"), "python": platform.python_version(),
              "offline": os.environ.get("HF_HUB_OFFLINE"), "datasets": [check(Path(d)) for d in args.datasets]}
    print(markdown(report))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"\nwrote {out}")
    return 1 if any(r["problems"] for r in report["datasets"]) else 0


if __name__ == "__main__":
    sys.exit(main())
