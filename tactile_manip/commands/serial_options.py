"""The serial-port options shared by the commands that open a board (`record`, `view`)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tactile_manip.sensors import SerialSensorConfig

PORT_HINT = ("name the board's serial port (`tactile-manip find-port` lists them), "
             "or pass --sim for the simulated sensor")
WIRE_FORMATS = ("supermag", "anyskin")  # mirrors tactile_manip.wire.WIRE_FORMATS (checked in the tests)
DEFAULT_WIRE_FORMAT, DEFAULT_BAUD = "supermag", 921600  # without --board: the SuperMag firmware's


def add_serial_options(p: argparse.ArgumentParser, source: argparse._MutuallyExclusiveGroup) -> None:
    """``--serial-number`` joins the command's source group; the port options get their own group."""
    source.add_argument("--serial-number", metavar="SN",
                        help="the board's USB serial number instead of --port (kept across replugs; see find-port)")
    g = p.add_argument_group("serial port")
    g.add_argument("--baud", type=int, default=None,
                   help="baud rate (default: the --board file's [wire] baudrate, else 921600)")
    g.add_argument("--wire-format", choices=WIRE_FORMATS, default=None,
                   help="the board's bytes: supermag (firmware/) or anyskin (ReSkin/AnySkin binary sketch); default: "
                        "the --board file's [wire] format, else supermag")
    g.add_argument("--board", "--layout", dest="layout", default="", metavar="NAME|FILE",
                   help="the board: a shipped board (supermag-4x4, anyskin-5, eflesh), generic:N or a board file "
                        "(.toml); default: the wire format's own board (--layout is the same option)")
    g.add_argument("--dtr", choices=("low", "high"), default="low",
                   help="DTR level while open: low for ESP32 boards behind a USB bridge (default), high for "
                        "native-USB boards such as the SAMD21 on AnySkin, which only write once DTR is high")
    g.add_argument("--rts", choices=("low", "high"), default="low", help="RTS level while open (default low)")


def check_sim_board(args: argparse.Namespace) -> None:
    """Refuse ``--sim`` with another board than the SuperMag one it simulates (ValueError saying what does)."""
    if getattr(args, "sim", False) and args.layout and args.layout != "supermag-4x4":
        raise ValueError(f"--sim simulates the SuperMag board, not --board {args.layout}: serve that board's bytes "
                         f"with `tactile-manip emulate --board {args.layout} --link PAD` and read them with "
                         f"--port PAD --board {args.layout}")


def serial_config(args: argparse.Namespace) -> SerialSensorConfig:
    """The SerialSensorConfig the options describe (ValueError naming a bad value; an empty --port or
    --serial-number is refused, never read as "no port")."""
    from tactile_manip.checks import check_nonblank
    from tactile_manip.sensors import SerialSensorConfig

    for flag, value in (("--port", args.port), ("--serial-number", args.serial_number)):
        if value is not None:
            check_nonblank(flag, value, hint=PORT_HINT)
    wire_format, baud = args.wire_format, args.baud
    if args.layout and (wire_format is None or baud is None):  # the board file says how its frames travel
        from tactile_manip.boards import load_board

        wire = load_board(args.layout).wire
        wire_format, baud = wire_format or wire.format, baud or wire.baudrate
    return SerialSensorConfig(port=args.port or "", serial_number=args.serial_number or "",
                              baudrate=baud or DEFAULT_BAUD, wire_format=wire_format or DEFAULT_WIRE_FORMAT,
                              layout=args.layout, dtr=args.dtr == "high", rts=args.rts == "high")
