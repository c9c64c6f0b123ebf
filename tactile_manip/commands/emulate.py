"""``tactile-manip emulate``: the sensor board's firmware emulated on a pseudo-terminal.

Prints the device path to open as the first line of stdout, streams frames at 125 Hz from scripted presses
on the simulator, and, when the stream ends, prints a one-line JSON report (frames sent, damaged frames).
Stops on Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import argparse


def _window(text: str) -> tuple[float, float]:
    start, sep, duration = text.partition(":")
    try:
        return float(start), float(duration)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected START_S:DURATION_S, e.g. 2.0:0.5, got {text!r}") from None


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--press", action="append", default=[], metavar="SPEC",
                   help="scripted press 'NAME[,t=S][,force=N][,x=MM][,y=MM][,yaw=DEG][,rise=S][,hold=S][,size=MM]', "
                        "e.g. 'letter_r,t=1,force=10,yaw=30' (repeatable)")
    p.add_argument("--period-s", type=float, default=None, help="repeat the press script with this period, s")
    p.add_argument("--rate-hz", type=float, default=125.0, help="frame rate, Hz (default 125)")
    p.add_argument("--seed", type=int, default=0, help="seed of the chip noise and the faults")
    p.add_argument("--temperature", action="store_true", help="also send chip temperatures (flags bit 0)")
    p.add_argument("--wire-format", choices=("supermag", "anyskin"), default=None,
                   help="the bytes: our frames (supermag) or the ReSkin/AnySkin binary sketch's (anyskin: float32 per "
                        "chip, CRLF); default: the wire format the board names (our frames when no --board)")
    p.add_argument("--board", "--layout", dest="layout", default="", metavar="NAME|FILE",
                   help="the board whose chips the frames carry (anyskin-5, eflesh, or a board file of that wire "
                        "format), read at its chips' places from the simulated pad; default: the wire format's own")
    p.add_argument("--frames", type=int, default=None, help="stop after this many frames")
    p.add_argument("--duration-s", type=float, default=None, help="stop after this long, s")
    p.add_argument("--linger-s", type=float, default=0.5, help="keep the port open after the last frame, s")
    p.add_argument("--link", default=None, metavar="PATH",
                   help="symlink kept pointing at the current pty (needed for --disconnect)")
    p.add_argument("--clock", choices=("device", "host"), default="device",
                   help="t_mcu_us: time on the schedule (device) or host monotonic us at write (host)")
    f = p.add_argument_group("faults")
    f.add_argument("--bit-flip-rate", type=float, default=0.0, help="per-frame probability of one flipped bit")
    f.add_argument("--drop-byte-rate", type=float, default=0.0, help="per-frame probability of one missing byte")
    f.add_argument("--truncate-rate", type=float, default=0.0, help="per-frame probability of a cut-short frame")
    f.add_argument("--stall", type=_window, action="append", default=[], metavar="START_S:DURATION_S",
                   help="no frames in this window (repeatable)")
    f.add_argument("--disconnect", type=_window, action="append", default=[], metavar="START_S:DURATION_S",
                   help="the port disappears in this window and returns as a new pty behind --link (repeatable)")


def run(args: argparse.Namespace) -> int:
    import dataclasses
    import json
    import signal
    import sys
    import threading

    from tactile_manip.lifeline import Lifeline
    from tactile_manip.sensors.simulated.contacts import parse_press
    from tactile_manip.sensors.simulated.emulator import EmulatorConfig, FaultConfig, FirmwareEmulator

    if args.linger_s < 0:
        raise ValueError(f"--linger-s must be >= 0, got {args.linger_s}")
    wire_format = args.wire_format
    if wire_format is None:
        from tactile_manip.boards import load_board

        wire_format = load_board(args.layout).wire.format if args.layout else "supermag"
    config = EmulatorConfig(rate_hz=args.rate_hz, seed=args.seed, temperature=args.temperature, link=args.link,
                            frames=args.frames, duration_s=args.duration_s, clock=args.clock, period_s=args.period_s,
                            wire_format=wire_format, board=args.layout)
    faults = FaultConfig(bit_flip_rate=args.bit_flip_rate, drop_byte_rate=args.drop_byte_rate,
                         truncate_rate=args.truncate_rate, stalls=tuple(args.stall),
                         disconnects=tuple(args.disconnect))
    emulator = FirmwareEmulator(config, presses=[parse_press(s) for s in args.press], faults=faults)
    stop = threading.Event()
    stopped_by: list[int] = []

    def stop_on(sig: int, _frame) -> None:
        stopped_by.append(sig)
        stop.set()

    previous = {sig: signal.signal(sig, stop_on) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        # the link goes with this process even when it is killed outright (SIGKILL): a watchdog removes it
        with emulator, Lifeline(links=[(emulator.path, emulator.device)] if config.link else []):
            print(emulator.path, flush=True)
            print(f"emulate: streaming {config.rate_hz:g} Hz on {emulator.path}"
                  + (f" (-> {emulator.device})" if config.link else "") + "; Ctrl-C to stop",
                  file=sys.stderr, flush=True)
            report = emulator.run(stop)
            print(json.dumps({"event": "done", **dataclasses.asdict(report)}), flush=True)
            stop.wait(args.linger_s)  # let a reader drain the last frames before the port disappears
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if stopped_by:  # stopped by a signal: the shell's code for it (130 for Ctrl-C, 143 for SIGTERM)
        print(f"emulate: stopped by {signal.Signals(stopped_by[0]).name}", file=sys.stderr, flush=True)
        return 128 + stopped_by[0]
    return 0
