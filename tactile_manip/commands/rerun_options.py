"""The Rerun options shared by the commands that stream to Rerun (`view`, `trials`)."""

from __future__ import annotations

import argparse
import ipaddress


def add_rerun_options(p: argparse.ArgumentParser, *, what: str) -> None:
    """``--rerun`` and where it goes: ``--save F.rrd``, ``--spawn`` (the default) or ``--serve`` on ``--bind``."""
    g = p.add_argument_group("Rerun (extra 'viz')")
    g.add_argument("--rerun", action="store_true", help=f"stream {what} to Rerun")
    sink = g.add_mutually_exclusive_group()
    sink.add_argument("--save", metavar="RRD", help="with --rerun: write the recording to this .rrd file")
    sink.add_argument("--spawn", action="store_true", help="with --rerun: start a Rerun viewer (the default)")
    sink.add_argument("--serve", action="store_true",
                      help="with --rerun: serve the stream over gRPC for viewers to connect to (`rerun --connect URL`)")
    g.add_argument("--bind", default="127.0.0.1",
                   help="IP address the spawned viewer or server listens on, without a port (default 127.0.0.1: "
                        "this machine only; ::1 for IPv6, 0.0.0.0 or :: for every interface)")
    g.add_argument("--rerun-port", type=int, default=9876, help="its port (default 9876)")


def check_rerun_options(args: argparse.Namespace) -> None:
    """The sink options only with --rerun, a valid port and address; with --save, the file is refused if it exists
    without --force (checked before a device or a run folder is opened)."""
    used = [flag for flag, on in (("--save", args.save is not None), ("--spawn", args.spawn), ("--serve", args.serve))
            if on]
    if used and not args.rerun:
        raise ValueError(f"{used[0]} needs --rerun")
    if not 0 < args.rerun_port < 65536:
        raise ValueError(f"--rerun-port: expected 1..65535, got {args.rerun_port}")
    args.bind = check_bind(args.bind)
    if args.rerun:
        from tactile_manip.interop.rerun_log import require_rerun
        from tactile_manip.outputs import check_output_file

        require_rerun(f"{args.command} --rerun")
        if args.save is not None:
            args.save = str(check_output_file(args.save, force=getattr(args, "force", False)))


def check_bind(text: str) -> str:
    """``--bind`` as the IP address the ``rerun`` program takes (``localhost`` as 127.0.0.1, brackets around an
    IPv6 address dropped); ValueError for an address with a port, or for a name."""
    value = text.strip()
    if value == "localhost":
        return "127.0.0.1"
    try:
        return str(ipaddress.ip_address(value[1:-1] if value.startswith("[") and value.endswith("]") else value))
    except ValueError:
        pass
    host, sep, port = value.rpartition(":")
    if sep and port.isdigit() and (":" not in host or (host.startswith("[") and host.endswith("]"))):
        raise ValueError(f"--bind takes an address without a port (got {text!r}); give the port with --rerun-port")
    raise ValueError(f"--bind: expected an IP address of this machine, such as 127.0.0.1, ::1 or 0.0.0.0, "
                     f"got {text!r}")
