"""From a VBTS calibration to a trained model on collected pairs, on the emulated MBTS and the simulated camera.

The same steps run on a real rig with ``SerialSensor`` + ``OpenCVCamera`` and the gripper's force (see
docs/collection.md); here every part is the simulated twin behind the same interface:

1. calibrate the VBTS from a still press of a 4 mm-radius ball (the lookup table and the pad alignment);
2. collect synchronized pairs: the firmware emulator streams real bytes at 125 Hz on a pty, read by the serial
   driver; the simulated camera renders DTact frames at 30 Hz (with jitter and dropped frames); both follow
   one press script whose force triggers the recorder at 10 N;
3. write the paired dataset, train a tiny CVAE with ``tactile-manip train``, export it, and evaluate it with
   ``tactile-manip evaluate`` on the unseen hex bar, all on the collected file as it is.

Needs the extras 'serial' (the serial driver reads the emulated board) and 'train' (torch, onnx and
onnxruntime, for the model); without one it stops at once with the line that installs it.

Run: python examples/collect_walkthrough.py [--presses 18]  (about 1-2 minutes; writes examples_out/collect/)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tactile_manip.cli import main as cli
from tactile_manip.collection.camera_sim import SimulatedCamera, SimulatedCameraConfig
from tactile_manip.collection.collect import CollectConfig, PairCollector
from tactile_manip.collection.collect_sim import SimulatedRig, calibrate_simulated, random_presses
from tactile_manip.sensors.simulated.emulator import FaultConfig
from tactile_manip.collection.pair_log import dataset_from_pair_logs
from tactile_manip.data import save_dataset
from tactile_manip.extras import MissingExtraError, require
from tactile_manip.sim.vbts import lookup_table

OUT = Path("examples_out/collect")
TINY_TRAIN = 'preset = "small"\nepochs = 2\nbatch_size = 8\nlr = 3e-3\nthreads = 1\n'
# optional packages of the walkthrough: module of EXTRAS -> what needs it
NEEDS = {"serial": "reading the emulated board", "torch": "training", "onnx": "export",
         "onnxruntime": "export's parity check and evaluate"}


def check_extras() -> None:
    """Stop with one line naming the extra to install, before any work, when an optional package is missing."""
    for module, purpose in NEEDS.items():
        try:
            require(module, f"the walkthrough ({purpose})")
        except MissingExtraError as e:
            raise SystemExit(f"collect_walkthrough.py: error: {e}") from None


def calibrate(seed: int):
    """Step 1: reference frames, then a still 4.5 N press of the ball; check against the camera's truth."""
    camera_cfg = SimulatedCameraConfig(seed=seed)
    with SimulatedCamera(camera_cfg) as camera:
        cal = calibrate_simulated(camera, radius_mm=4.0, force_n=4.5, frames=10)
    cal.save(OUT / "vbts_calibration.npz")
    true = lookup_table(camera_cfg.lookup_table)
    n = min(true.size, cal.table_mm.size)
    err = np.abs(cal.table_mm[1:n] - true[1:n])
    fit = cal.report["presses"][0]
    print(f"1. calibration: ball pressed {fit['press_depth_mm']:.3f} mm, table 0-{cal.report['table_max_mm']:.2f} mm; "
          f"error vs the camera's true table max {err.max():.3f} mm, mean {err.mean():.3f} mm")
    return cal, camera_cfg


def collect(cal, camera_cfg: SimulatedCameraConfig, presses: int, seed: int) -> Path:
    """Step 2: the rig, its baseline and reference, then one pair per press at the 10 N threshold."""
    script = random_presses(["allen_key", "letter_r", "hex_bar"], presses, rng=np.random.default_rng(seed))
    camera = SimulatedCameraConfig(seed=seed, jitter_s=0.002, drop_rate=0.1, lookup_table=camera_cfg.lookup_table)
    log_path = OUT / "pairs.tmpairs"
    print(f"2. collecting: solving {presses} presses for both sensors, then {script[-1].end_s:.0f} s of streaming")
    with SimulatedRig(script, seed=seed, camera=camera, faults=FaultConfig(bit_flip_rate=0.02)) as rig:
        collector = PairCollector(rig.sensor, rig.camera, cal, rig.force, log_path,
                                  config=CollectConfig(threshold_n=10.0, pairs_per_press=2, tolerance_s=0.005),
                                  header={"mode": "simulated", "script_start_host_s": rig.start_host_s})
        collector.prepare()
        with tqdm(total=presses, unit="press", desc="   pairs") as bar:
            summary = collector.run(presses=presses, progress=lambda s: bar.update(s.complete_presses - bar.n))
    print(f"   {summary.pairs} pairs from {summary.complete_presses} presses, {summary.unpaired} unpaired; "
          f"|t_field - t_depth| max {summary.max_abs_dt_s * 1e3:.2f} ms (tolerance 5 ms); "
          f"camera dropped {summary.camera_dropped} frames")
    data = dataset_from_pair_logs([log_path], test_objects=["hex_bar"], validation_fraction=0.2)
    path = save_dataset(OUT / "pairs.npz", data)
    print(f"   wrote {path}: " + ", ".join(f"{s} {len(data.indices(s))}" for s in ("train", "val", "test")))
    return path


def train_and_evaluate(data: Path) -> None:
    """Step 3: the CVAE commands on the collected file, unconverted."""
    (OUT / "tiny.toml").write_text(TINY_TRAIN)
    run = OUT / "run"
    # --force: the walkthrough owns OUT and starts over in it on every run
    steps = [["train", "--config", str(OUT / "tiny.toml"), "--data", str(data), "--out", str(run), "--force"],
             ["export", "--checkpoint", str(run / "best.pt"), "--out", str(OUT / "model.onnx"), "--data", str(data),
              "--force"],
             ["evaluate", "--data", str(data), "--model", f"Tiny={OUT / 'model.onnx'}", "--out", str(OUT / "eval"),
              "--force"]]
    for argv in steps:
        print(f"3. tactile-manip {' '.join(argv)}")
        if cli(argv) != 0:
            raise SystemExit(f"tactile-manip {argv[0]} failed")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--presses", type=int, default=18, help="presses to collect (cycling Allen key, R, hex bar)")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    check_extras()
    OUT.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cal, camera_cfg = calibrate(args.seed)
    data = collect(cal, camera_cfg, args.presses, args.seed)
    train_and_evaluate(data)
    print(f"done in {time.perf_counter() - t0:.0f} s; see {OUT}/eval/table.md and gallery.png")


if __name__ == "__main__":
    main()
