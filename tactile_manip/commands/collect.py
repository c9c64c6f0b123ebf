"""``tactile-manip collect``: calibrate the VBTS, record synchronized MBTS/VBTS pairs, write a paired dataset.

- ``collect calibrate``: reference frames, then a still ball press of known radius -> the lookup table and the
  pad alignment, saved as a calibration ``.npz``;
- ``collect run``: MBTS at 125 Hz and VBTS at ~30 Hz, each depth frame paired with the nearest MBTS frame within
  the tolerance, triggered on the press force threshold; a crash-safe pair log (``OUT`` with ``.tmpairs``) and,
  at the end, the dataset ``OUT`` that ``tactile-manip train`` reads;
- ``collect finalize``: the dataset from one or more pair logs (after a crash, or to merge sessions).

``--sim`` runs everything on the firmware emulator (a pty, read by the real serial driver) and the simulated
camera, driven by one press script. See ``docs/collection.md``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tactile_manip.commands.serial_options import PORT_HINT

CAMERA_HINT = "give the VBTS camera's OpenCV index or device path, or pass --sim for the simulated camera"


def _csv(text: str) -> list[str]:
    return [s.strip() for s in text.split(",") if s.strip()]


def _corners(text: str) -> tuple[tuple[float, float], ...]:
    try:
        pts = tuple(tuple(float(v) for v in p.split(",")) for p in text.split())
    except ValueError:
        pts = ()
    if len(pts) != 4 or any(len(p) != 2 for p in pts):
        raise argparse.ArgumentTypeError(f"expected four 'u,v' pixel pairs, e.g. '489,72 151,66 146,411 494,413', "
                                         f"got {text!r}")
    return pts


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    cal = _subcommand(sub, "calibrate", "ball-press calibration of the VBTS (lookup table + pad alignment)")
    src = cal.add_mutually_exclusive_group(required=True)
    src.add_argument("--sim", action="store_true", help="the simulated camera (known ground truth)")
    src.add_argument("--camera", help="OpenCV camera index or device path (needs the 'camera' extra)")
    cal.add_argument("--corners", type=_corners, default=None, metavar="'u,v u,v u,v u,v'",
                     help="camera pixels of the VBTS pad corners (-x,+y) (+x,+y) (+x,-y) (-x,-y) (real camera)")
    cal.add_argument("--pad-mm", type=float, default=21.0, help="side of the square the corners outline, mm")
    cal.add_argument("--mirror", choices=("x", "y", "none"), default="x",
                     help="VBTS pad frame -> MBTS pad frame in the symmetric gripper (default x)")
    cal.add_argument("--ball-radius-mm", type=float, required=True, help="radius of the calibration ball, mm")
    cal.add_argument("--press-depth-mm", type=float, default=None, help="known press depth (else from the edge)")
    cal.add_argument("--frames", type=int, default=10, help="frames averaged for the reference and the press")
    cal.add_argument("--sim-force-n", type=float, default=4.5, help="--sim: ball press force, N (4.5 N: ~1.8 mm)")
    cal.add_argument("--sim-table", choices=("sensor_1", "sensor_2"), default="sensor_1",
                     help="--sim: the simulated camera's true lookup table")
    cal.add_argument("--out", required=True, help="calibration file to write (.npz)")
    cal.add_argument("--force", action="store_true", help="overwrite an existing output file")

    rec = _subcommand(sub, "run", "record synchronized pairs and write a paired dataset")
    src = rec.add_mutually_exclusive_group(required=True)
    src.add_argument("--sim", action="store_true", help="emulated MBTS + simulated camera on one press script")
    src.add_argument("--port", help="serial port of the MBTS board (real rig; needs --camera)")
    rec.add_argument("--camera", help="OpenCV camera index or device path (real rig)")
    rec.add_argument("--calibration", required=True, help="file from `tactile-manip collect calibrate`")
    rec.add_argument("--out", required=True, help="dataset to write (.npz); the pair log goes next to it (.tmpairs)")
    rec.add_argument("--presses", type=int, default=20, help="presses to record (--sim: presses to script)")
    rec.add_argument("--objects", type=_csv, default=["allen_key", "letter_r"],
                     help="--sim: objects the script cycles over; real rig: the one object pressed")
    rec.add_argument("--test-objects", type=_csv, default=[], help="objects whose pairs form the test split")
    rec.add_argument("--val-fraction", type=float, default=0.1, help="last fraction of each other object -> val")
    rec.add_argument("--threshold-n", type=float, default=10.0, help="press force threshold (trigger), N")
    rec.add_argument("--release-n", type=float, default=2.0, help="re-arm below this force, N")
    rec.add_argument("--pairs-per-press", type=int, default=1, help="camera frames taken per press")
    rec.add_argument("--tolerance-ms", type=float, default=5.0, help="largest time between a pair's frames, ms")
    rec.add_argument("--camera-latency-ms", type=float, default=0.0, help="camera exposure-to-timestamp delay, ms")
    rec.add_argument("--ut-per-n", type=float, default=60.0,
                     help="real rig: force proxy from the MBTS, |field| uT per newton")
    rec.add_argument("--seed", type=int, default=0, help="--sim: script, sensor and noise seed")
    rec.add_argument("--camera-jitter-ms", type=float, default=0.0, help="--sim: camera exposure jitter (std), ms")
    rec.add_argument("--camera-drop-rate", type=float, default=0.0, help="--sim: probability of a dropped frame")
    rec.add_argument("--bit-flip-rate", type=float, default=0.0, help="--sim: MBTS frames with a flipped bit")
    rec.add_argument("--force", action="store_true", help="overwrite existing output files")

    fin = _subcommand(sub, "finalize", "write the dataset from pair logs (after a crash, or to merge sessions)")
    fin.add_argument("logs", nargs="+", help="pair logs (.tmpairs)")
    fin.add_argument("--out", required=True, help="dataset to write (.npz)")
    fin.add_argument("--test-objects", type=_csv, default=[], help="objects whose pairs form the test split")
    fin.add_argument("--val-fraction", type=float, default=0.1, help="last fraction of each other object -> val")
    fin.add_argument("--force", action="store_true", help="overwrite an existing output file")


def check_nonblank(name: str, value: str, *, hint: str) -> str:
    from tactile_manip.checks import check_nonblank as check  # numpy stays out of `--help`

    return check(name, value, hint=hint)


def run(args: argparse.Namespace) -> int:
    from tactile_manip.extras import require

    if not getattr(args, "sim", False):  # a typo first (an empty --port / --camera is not --sim), then the extras
        if getattr(args, "camera", None) is not None:
            check_nonblank("--camera", args.camera, hint=CAMERA_HINT)
        if getattr(args, "port", None) is not None:
            check_nonblank("--port", args.port, hint=PORT_HINT)
    if getattr(args, "camera", None) and not getattr(args, "sim", False):  # a real rig: its extras before any work
        require("cv2", "a real VBTS camera")
        if args.action == "run":
            require("serial", "a real MBTS board")
    if args.action == "calibrate":
        require("sklearn.isotonic", "fitting a calibration")
    return {"calibrate": _calibrate, "run": _record, "finalize": _finalize}[args.action](args)


def _fresh(path: Path, force: bool) -> Path:
    from tactile_manip.outputs import check_output_file

    return check_output_file(path, force=force)


def _calibrate(args: argparse.Namespace) -> int:
    import numpy as np

    from tactile_manip.collection.vbts_calibration import calibrate_ball

    out = _fresh(Path(args.out), args.force)
    if args.frames < 2:
        raise ValueError(f"--frames must be >= 2, got {args.frames}")
    if args.sim:
        from tactile_manip.collection.camera_sim import SimulatedCamera, SimulatedCameraConfig
        from tactile_manip.collection.collect_sim import calibrate_simulated
        from tactile_manip.sim.vbts import lookup_table

        camera = SimulatedCamera(SimulatedCameraConfig(lookup_table=args.sim_table, mirror=args.mirror))
        with camera:
            cal = calibrate_simulated(camera, radius_mm=args.ball_radius_mm, force_n=args.sim_force_n,
                                      frames=args.frames)
        true = lookup_table(args.sim_table)
        n = min(true.size, cal.table_mm.size)
        cal.report["table_error_vs_truth_mm"] = {"max": float(np.abs(cal.table_mm[1:n] - true[1:n]).max()),
                                                 "mean": float(np.abs(cal.table_mm[1:n] - true[1:n]).mean())}
    else:
        from tactile_manip.collection.camera_opencv import OpenCVCamera, OpenCVCameraConfig
        from tactile_manip.collection.vbts import PadAlignment

        if args.corners is None:
            raise ValueError("--corners is required with a real camera (the pad's four corners in the image)")
        check_nonblank("--camera", args.camera, hint=CAMERA_HINT)
        device = int(args.camera) if args.camera.isdigit() else args.camera
        with OpenCVCamera(OpenCVCameraConfig(device=device)) as camera:
            input("clear the pad (nothing touching it), then press Enter ")
            camera.drain()
            reference = [camera.read().image for _ in range(args.frames)]
            alignment = PadAlignment(corners_px=args.corners, camera_shape=reference[0].shape[:2], pad_mm=args.pad_mm,
                                     mirror=args.mirror)
            input(f"press the {2 * args.ball_radius_mm:g} mm ball into the pad centre, hold it still, press Enter ")
            camera.drain()
            press = [camera.read().image for _ in range(args.frames)]
        cal = calibrate_ball(alignment, reference, [press], args.ball_radius_mm,
                             press_depths_mm=[args.press_depth_mm])
    cal.save(out)
    fit = cal.report["presses"][0]
    print(f"ball: press depth {fit['press_depth_mm']:.3f} mm, contact radius {fit['contact_radius_mm']:.2f} mm at "
          f"({fit['centre_mm'][0]:.2f}, {fit['centre_mm'][1]:.2f}) mm; "
          f"table 0-{cal.report['table_max_mm']:.3f} mm over "
          f"{cal.report['table_levels']} grey levels" + (" (saturated)" if cal.report["saturated"] else ""))
    if "table_error_vs_truth_mm" in cal.report:
        e = cal.report["table_error_vs_truth_mm"]
        print(f"table vs the simulated camera's true table: max {e['max']:.4f} mm, mean {e['mean']:.4f} mm")
    print(f"wrote {out}")
    return 0


def _record(args: argparse.Namespace) -> int:
    import numpy as np

    from tactile_manip.collection.collect import CollectConfig
    from tactile_manip.collection.vbts_calibration import VbtsCalibration
    from tactile_manip.progress import progress_bar

    from tactile_manip.data import dataset_path

    if not args.sim:  # checked before any file is touched; an empty --port is not --sim
        check_nonblank("--port", args.port, hint=PORT_HINT)
    out = _fresh(dataset_path(args.out), args.force)
    log_path = _fresh(out.with_suffix(".tmpairs"), args.force)
    if args.presses < 1:
        raise ValueError(f"--presses must be >= 1, got {args.presses}")
    config = CollectConfig(threshold_n=args.threshold_n, release_n=args.release_n,
                           pairs_per_press=args.pairs_per_press, tolerance_s=args.tolerance_ms * 1e-3,
                           camera_latency_s=args.camera_latency_ms * 1e-3, object_name=args.objects[0])
    calibration = VbtsCalibration.load(args.calibration)
    bar, shown = None, None

    def progress(s) -> None:
        nonlocal bar, shown
        if bar is None:  # created once the streams run, so the solve time does not count as collecting
            bar = progress_bar(total=args.presses, unit="press", desc="collecting")
        if (s.complete_presses, s.pairs, s.unpaired) != shown:
            shown = (s.complete_presses, s.pairs, s.unpaired)
            bar.update(s.complete_presses - bar.n)
            bar.set_postfix(pairs=s.pairs, unpaired=s.unpaired, max_dt_ms=f"{s.max_abs_dt_s * 1e3:.1f}")

    try:
        if args.sim:
            summary = _record_sim(args, config, calibration, log_path, progress)
        else:
            summary = _record_real(args, config, calibration, log_path, progress)
    finally:
        if bar is not None:
            bar.close()
    from tactile_manip.collection.pair_log import dataset_from_pair_logs
    from tactile_manip.data import SPLITS, save_dataset

    data = dataset_from_pair_logs([log_path], test_objects=args.test_objects, validation_fraction=args.val_fraction)
    path = save_dataset(out, data)
    counts = ", ".join(f"{s} {len(data.indices(s))}" for s in SPLITS)
    print(f"{summary.complete_presses}/{summary.presses} presses complete, {summary.pairs} pairs, {summary.unpaired} "
          f"unpaired; |t_field - t_depth| max {summary.max_abs_dt_s * 1e3:.2f} ms, mean "
          f"{summary.mean_abs_dt_s * 1e3:.2f} ms (tolerance {args.tolerance_ms:g} ms); camera dropped "
          f"{summary.camera_dropped} frames")
    print(f"wrote {log_path} and {path} ({counts})")
    empty = [s for s in SPLITS if not np.any(data.split == s)]
    if empty:
        print(f"note: no {' / '.join(empty)} samples: `tactile-manip train` needs train and val, `evaluate` a test "
              "split (--test-objects, --val-fraction, or merge sessions with `collect finalize`)")
    return 0


def _record_sim(args, config, calibration, log_path: Path, progress):
    import numpy as np

    from tactile_manip.collection.camera_sim import SimulatedCameraConfig
    from tactile_manip.collection.collect import PairCollector
    from tactile_manip.collection.collect_sim import SimulatedRig, random_presses
    from tactile_manip.sensors.simulated.emulator import FaultConfig

    rng = np.random.default_rng(args.seed)
    presses = random_presses(args.objects, args.presses, rng=rng, lead_s=3.0)
    camera = SimulatedCameraConfig(seed=args.seed, jitter_s=args.camera_jitter_ms * 1e-3,
                                   drop_rate=args.camera_drop_rate, mirror=calibration.alignment.mirror)
    print(f"collect: solving {len(presses)} presses for both sensors ...", flush=True)
    with SimulatedRig(presses, seed=args.seed, camera=camera,
                      faults=FaultConfig(bit_flip_rate=args.bit_flip_rate)) as rig:
        collector = PairCollector(rig.sensor, rig.camera, calibration, rig.force, log_path, config=config,
                                  header={"mode": "simulated", "seed": args.seed, "objects": args.objects,
                                          "script_start_host_s": rig.start_host_s})
        collector.prepare()
        return collector.run(presses=args.presses, progress=progress)


def _record_real(args, config, calibration, log_path: Path, progress):
    import signal
    import threading

    from tactile_manip.collection.camera_opencv import OpenCVCamera, OpenCVCameraConfig
    from tactile_manip.collection.collect import PairCollector
    from tactile_manip.collection.force import FieldForce
    from tactile_manip.sensors.config import SerialSensorConfig
    from tactile_manip.sensors.serial_sensor import SerialSensor

    if args.camera is None:
        raise ValueError("--port needs --camera (the VBTS camera's OpenCV index or device path)")
    check_nonblank("--camera", args.camera, hint=CAMERA_HINT)
    device = int(args.camera) if args.camera.isdigit() else args.camera
    h, w = calibration.alignment.camera_shape
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        with SerialSensor(SerialSensorConfig(port=args.port)) as sensor, \
                OpenCVCamera(OpenCVCameraConfig(device=device, width_px=w, height_px=h)) as camera:
            collector = PairCollector(sensor, camera, calibration, FieldForce(sensor, args.ut_per_n), log_path,
                                      config=config, header={"mode": "real", "object": args.objects[0]})
            input("open the gripper (pads free), then press Enter ")
            collector.prepare()
            print("collect: press the object; Ctrl-C ends the session", flush=True)
            try:
                return collector.run(presses=args.presses, stop=stop, progress=progress)
            except KeyboardInterrupt:
                return collector.summary
    finally:
        signal.signal(signal.SIGTERM, previous)


def _finalize(args: argparse.Namespace) -> int:
    from tactile_manip.collection.pair_log import dataset_from_pair_logs, read_pair_log
    from tactile_manip.data import SPLITS, dataset_path, save_dataset

    out = _fresh(dataset_path(args.out), args.force)
    logs = [read_pair_log(p) for p in args.logs]
    for log in logs:
        if log.truncated_bytes:
            print(f"{log.path}: {len(log)} pairs, ignored a torn tail of {log.truncated_bytes} bytes (a crash)")
        if log.skipped_bytes:
            print(f"{log.path}: skipped {log.skipped_bytes} damaged bytes in {log.damaged_records} place(s)")
    data = dataset_from_pair_logs(logs, test_objects=args.test_objects, validation_fraction=args.val_fraction)
    path = save_dataset(out, data)
    counts = ", ".join(f"{s} {len(data.indices(s))}" for s in SPLITS)
    print(f"wrote {path}: {len(data)} pairs from {len(logs)} log(s) ({counts})")
    return 0


def _subcommand(sub, name: str, what: str) -> argparse.ArgumentParser:
    """A subcommand whose one line shows in the list and heads its own --help."""
    return sub.add_parser(name, help=what, description=what)
