"""``tactile-manip record``: write a sensor's frames, host and device timestamps and health to a file.

The file survives a crash: it is append-only and synced at least every ``--sync-every-s`` (0.5 s), so a
killed recorder leaves every frame up to about that long before the kill. Read it with
``tactile_manip.sensors.read_recording`` or replay it with ``ReplaySensor``.
"""

from __future__ import annotations

import argparse

from tactile_manip.commands.serial_options import add_serial_options, check_sim_board, serial_config


def add_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--port", help="serial port of the board (or the emulator's path)")
    src.add_argument("--sim", action="store_true", help="record the simulated sensor instead")
    p.add_argument("--out", required=True, help="recording file to write (e.g. data/rec.tmrec)")
    p.add_argument("--seconds", type=float, default=None, help="stop after this long (default: until Ctrl-C)")
    p.add_argument("--press", action="append", default=[], metavar="SPEC",
                   help="with --sim: scripted press, as for `tactile-manip emulate` (repeatable)")
    p.add_argument("--sync-every-s", type=float, default=0.5, help="flush and fsync at least this often, s")
    p.add_argument("--health-every-s", type=float, default=1.0, help="health record (and status line) period, s")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.add_argument("--quiet", action="store_true", help="no status line per health record")
    add_serial_options(p, src)


def run(args: argparse.Namespace) -> int:
    import signal
    import sys
    import threading

    from tactile_manip.extras import require
    from tactile_manip.sensors import Recorder, SerialSensor, SimulatedSensor, parse_press

    from tactile_manip.outputs import check_output_file

    out = check_output_file(args.out, force=args.force)
    if not 0 < args.sync_every_s <= 1.0:
        raise ValueError(f"--sync-every-s must be in (0, 1], got {args.sync_every_s}")
    if args.seconds is not None and not args.seconds > 0:
        raise ValueError(f"--seconds must be > 0, got {args.seconds}")
    if args.press and not args.sim:
        raise ValueError("--press scripts the simulated sensor: use it with --sim")
    check_sim_board(args)
    if args.sim:
        sensor = SimulatedSensor()
    else:  # an empty --port is refused by serial_config, never read as "no port" (that once recorded --sim)
        config = serial_config(args)
        require("serial", "recording a serial port")  # before the file or the port is touched
        sensor = SerialSensor(config)
    presses = [parse_press(s) for s in args.press]
    stop = threading.Event()
    terminated: list[bool] = []

    def on_sigterm(*_) -> None:  # the recording ends cleanly, then the command exits 143
        terminated.append(True)
        stop.set()

    previous = signal.signal(signal.SIGTERM, on_sigterm)

    def status(h) -> None:
        if not args.quiet:
            print(f"record: {h.uptime_s:6.1f} s  frames {h.frames}  {h.rate_hz:6.1f} Hz  gaps {h.seq_gaps}  "
                  f"crc {h.crc_errors}  resync {h.resync_bytes} B  reconnects {h.reconnects}"
                  + (f"  last error: {h.last_error}" if h.last_error else ""), file=sys.stderr, flush=True)

    try:
        with sensor:
            if presses:
                sensor.play(presses)
            print(f"record: {sensor.source} -> {out} (Ctrl-C to stop)", file=sys.stderr, flush=True)
            summary = Recorder(sensor, out, sync_every_s=args.sync_every_s,
                               health_every_s=args.health_every_s).run(duration_s=args.seconds, stop=stop,
                                                                       on_health=status)
    except KeyboardInterrupt:
        print(f"record: stopped; {out} is complete up to the interrupt", file=sys.stderr)
        raise  # Ctrl-C: the CLI exits 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    print(f"wrote {summary.frames} frames ({summary.seconds:.1f} s) to {out}")
    if terminated:
        print("record: stopped by SIGTERM", file=sys.stderr)
        return 143
    return 0
