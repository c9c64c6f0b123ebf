"""``tactile-manip find-port``: list the serial ports that may be the sensor board."""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--all", action="store_true", help="also list ports without USB ids (built-in UARTs, ...)")


def run(args: argparse.Namespace) -> int:
    import sys

    from tactile_manip.extras import require
    from tactile_manip.sensors.ports import list_ports

    require("serial.tools.list_ports", "find-port")
    ports = list_ports(include_all=args.all)
    if not ports:
        print("find-port: no USB serial port found. Is the board plugged in with a data cable? On Linux, is your "
              "user in the 'dialout' group? (`--all` lists every port; the emulator prints its own path)",
              file=sys.stderr)
        return 1
    print(f"{'port':<24}{'likely':<8}{'open with':<12}description")
    for p in ports:
        dtr = "--dtr high" if p.native_usb else ("--dtr low" if p.likely else "")
        print(f"{p.device:<24}{'yes' if p.likely else '':<8}{dtr:<12}{p.description}"
              + (f"  [{p.bridge}]" if p.bridge else "") + (f"  {p.hwid}" if p.hwid and p.hwid != "n/a" else ""))
    print("\nopen one with e.g. `tactile-manip view --port PORT`, or by its serial number (SER= above, kept across "
          "replugs) with `--serial-number SN`. ESP32 boards usually show a CP210x, CH340/CH9102 or FTDI bridge "
          "(DTR low, the default); native-USB boards (SAMD21 on ReSkin/AnySkin, Espressif USB) need `--dtr high`, "
          "and AnySkin boards `--wire-format anyskin`")
    return 0
