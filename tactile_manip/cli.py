"""The ``tactile-manip`` command line: one entry point, subcommands looked up in an explicit table.

Each subcommand lives in ``tactile_manip.commands.<module>`` with ``add_arguments(parser)`` and
``run(args) -> int``; command modules import their heavy dependencies inside ``run``, so ``--help`` is
fast. Errors this package raises on purpose (bad configs, missing files, bad values) print one line and
exit with status 2; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from tactile_manip.errors import TactileManipError
from tactile_manip.version import __version__

# name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("tactile_manip.commands.demo", "press the paper's objects on the simulated sensor pair"),
    "simulate": ("tactile_manip.commands.simulate", "generate a paired dataset from a config"),
    "import": ("tactile_manip.commands.import_data", "make a paired dataset from plain arrays (.npy, .npz, HDF5)"),
    "show": ("tactile_manip.commands.show", "render a sample (depth image and 4x4x3 field) to PNG"),
    "params": ("tactile_manip.commands.params", "list every simulator parameter with source and range"),
    "train": ("tactile_manip.commands.train", "train a SuperMag CVAE on a paired dataset"),
    "export": ("tactile_manip.commands.export", "export a trained checkpoint to ONNX with its metadata"),
    "evaluate": ("tactile_manip.commands.evaluate", "reproduce SuperMag's Table I on the unseen test objects"),
    "emulate": ("tactile_manip.commands.emulate", "emulate the sensor board's firmware on a pseudo-terminal"),
    "record": ("tactile_manip.commands.record", "record a sensor's frames and health to a crash-safe file"),
    "find-port": ("tactile_manip.commands.find_port", "list serial ports that may be the sensor board"),
    "view": ("tactile_manip.commands.view", "show the 4x4x3 field of a sensor live (or save a snapshot)"),
    "trials": ("tactile_manip.commands.trials", "run grasp-estimate-reorient trials per method and report"),
    "score": ("tactile_manip.commands.score", "re-score a saved trial run at another tolerance (no re-run)"),
    "collect": ("tactile_manip.commands.collect", "calibrate the VBTS and record synchronized MBTS/VBTS pairs"),
    "bench": ("tactile_manip.commands.bench", "speed vs error of every method and runtime on this machine"),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tactile-manip", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"tactile_manip {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module, help_text) in COMMANDS.items():
        cmd = sub.add_parser(name, help=help_text, description=help_text)
        importlib.import_module(module).add_arguments(cmd)
        cmd.set_defaults(_module=module)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(importlib.import_module(args._module).run(args) or 0)
    except (TactileManipError, ValueError, FileNotFoundError) as e:
        print(f"tactile-manip {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"tactile-manip {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
