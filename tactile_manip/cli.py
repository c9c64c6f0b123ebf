"""The ``tactile-manip`` command line: one entry point, subcommands looked up in an explicit table.

Each subcommand lives in ``tactile_manip.commands.<module>`` with ``add_arguments(parser)`` and
``run(args) -> int``; command modules import their heavy dependencies inside ``run``, so ``--help`` is
fast. :func:`main` is the one place that turns errors into exit statuses: errors this package raises on
purpose, bad values (ValueError), file-system errors (the OSError family: missing, unreadable or unwritable
paths) and a missing optional package (the line names its extra and install command) print one line
``tactile-manip CMD: error: ...`` and exit with status 2, as does a bad command line (argparse's refusal, without
its usage block); Ctrl-C exits with 130 and SIGTERM with 143 (raised as :class:`Terminated`, a
KeyboardInterrupt, so what a command cleans up on Ctrl-C it cleans up on SIGTERM too), a closed stdout
(``| head``) quietly with 141; anything else is a bug and keeps its traceback. Warnings raised while a command
runs (numpy's overflow on a file of 1e300 values) are held until it ends: shown if it succeeds or crashes,
dropped if it stops on an expected error, whose one line is then all that prints.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading
import warnings
from collections.abc import Sequence
from typing import NoReturn

from tactile_manip.errors import TactileManipError
from tactile_manip.extras import missing_extra_message
from tactile_manip.version import __version__

# name -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("tactile_manip.commands.demo", "press the paper's objects and unseen rods in simulation; table and PNGs"),
    "simulate": ("tactile_manip.commands.simulate",
                 "make a simulated dataset: readings and depth images, or probe presses on any board"),
    "import": ("tactile_manip.commands.import_data",
               "make a dataset from your own arrays or from a probe rig's sensor and label logs"),
    "fit-board": ("tactile_manip.commands.fit_board",
                  "fit a board file's twin (magnets, press kernel, chip readouts, rig frame) to your probe logs"),
    "simulate-log": ("tactile_manip.commands.simulate_log",
                     "a fitted board's simulated reading at every row of a probe log, with its explained variance"),
    "show": ("tactile_manip.commands.show", "draw a dataset sample or one simulated press as a PNG"),
    "params": ("tactile_manip.commands.params", "list the simulator's parameters: default, unit, range, source"),
    "train": ("tactile_manip.commands.train",
              "train a model on a dataset: depth images, contact position and force, or the angle"),
    "export": ("tactile_manip.commands.export",
               "convert a trial run, recording or pair log to LeRobot, Rerun or MCAP; a trained model to ONNX"),
    "export-model": ("tactile_manip.commands.export_model",
                     "write a trained checkpoint as ONNX (image model, contact model, or an angle head into a pose "
                     "model), checked against torch; the same as export --checkpoint"),
    "evaluate": ("tactile_manip.commands.evaluate",
                 "score models against baselines on test presses: depth images and angles, or contact"),
    "emulate": ("tactile_manip.commands.emulate",
                "serve a simulated sensor board on a pseudo-terminal, to try the tools without hardware"),
    "record": ("tactile_manip.commands.record", "record a sensor's frames to a file that survives a crash"),
    "find-port": ("tactile_manip.commands.find_port", "list serial ports that may be the sensor board"),
    "view": ("tactile_manip.commands.view",
             "watch a sensor's field live (board or simulation) or replay a recording; or stream it to Rerun"),
    "trials": ("tactile_manip.commands.trials",
               "run a scene's task (reorient the rod, place it in a slot, or grip it at a target force) per "
               "method on the same presentations, simulated or on an FR3, and report"),
    "calibrate": ("tactile_manip.commands.calibrate",
                  "calibrate a model's confidence to the chance its angle is within tolerance"),
    "score": ("tactile_manip.commands.score", "re-score a saved trial run at another tolerance, without re-running"),
    "collect": ("tactile_manip.commands.collect",
                "collect paired training data: calibrate the VBTS, record paired presses (real sensors, or --sim)"),
    "bench": ("tactile_manip.commands.bench", "measure speed against error of every method and runtime here"),
}


class _Version(argparse.Action):
    """``--version``: the version and which path the pose stage runs (looked up only when asked: the pose
    kernel's module imports numpy)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS, **kwargs) -> None:
        super().__init__(option_strings, dest=dest, default=argparse.SUPPRESS, nargs=0,
                         help="show the version and which path the pose stage runs (C kernel or numpy), and exit")

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        from tactile_manip.perception import pose_kernel

        print(f"tactile_manip {__version__}\npose stage: {pose_kernel.describe()}")  # stdout, as argparse's version
        parser.exit()


class _Parser(argparse.ArgumentParser):
    """argparse that refuses a bad command line in one line, without the usage block (``--help`` shows it):
    ``tactile-manip export: error: argument --format: invalid choice: 'parquet' (choose from ...) (see
    `tactile-manip export --help`)``, exit status 2. Its subparsers are of this class too, and an unrecognized
    argument is reported by the innermost (sub)command given."""

    _command_action: argparse.Action | None = None  # the subparsers action, once added

    def add_subparsers(self, **kwargs):
        kwargs.setdefault("parser_class", type(self))
        self._command_action = super().add_subparsers(**kwargs)
        return self._command_action

    def parse_args(self, args=None, namespace=None):
        namespace, extra = self.parse_known_args(args, namespace)
        if extra:
            self._innermost(namespace).error(f"unrecognized arguments: {' '.join(extra)}")
        return namespace

    def _innermost(self, namespace: argparse.Namespace) -> _Parser:
        action = self._command_action
        sub = action.choices.get(getattr(namespace, action.dest, None)) if action is not None else None
        return sub._innermost(namespace) if isinstance(sub, _Parser) else self

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see `{self.prog} --help`)\n")


class _HeldWarnings:
    """Holds the warnings raised inside the ``with`` block and shows them, where they were raised, when it ends,
    unless :meth:`drop` was called. The filters in force still apply: ``-W error`` still raises at the warning."""

    def __enter__(self) -> _HeldWarnings:
        self._catcher = warnings.catch_warnings(record=True)
        self._held = self._catcher.__enter__()
        self._dropped = False
        return self

    def drop(self) -> None:
        """Show nothing at the end: the command failed on its input and its error line says all there is."""
        self._dropped = True

    def __exit__(self, *exc_info) -> None:
        self._catcher.__exit__(*exc_info)
        for w in [] if self._dropped else self._held:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno, w.file, w.line)


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived while a command ran (``kill``, a scheduler's stop, the end of ``timeout``)."""


class _SigtermRaises:
    """Inside the ``with`` block, SIGTERM raises :class:`Terminated` where the command is, so its ``finally`` and
    ``except BaseException`` cleanups run; a second SIGTERM during that cleanup ends the process at once. Only the
    main thread can hold a signal handler: elsewhere this does nothing.

    Python runs a signal handler at the next instruction of the main thread, which may be inside a weakref
    callback, a ``__del__`` or an import lock's cleanup: there an exception is printed as "Exception ignored" and
    dropped, and the command would run on to exit 0. So while the block is open an unraisable :class:`Terminated`
    is delivered again, to land in the command's own code."""

    def __enter__(self) -> _SigtermRaises:
        self._installed = threading.current_thread() is threading.main_thread()
        self._raised = False  # the first SIGTERM became a Terminated
        self._redelivering = False  # that Terminated was dropped, and the signal is on its way again
        if self._installed:
            self._previous = signal.signal(signal.SIGTERM, self._raise)
            self._previous_hook = sys.unraisablehook
            sys.unraisablehook = self._unraisable
        return self

    def _raise(self, signum, frame) -> NoReturn:
        if self._raised and not self._redelivering:  # a second SIGTERM: die as the default handler would
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGTERM)
        self._raised, self._redelivering = True, False
        raise Terminated()

    def _unraisable(self, info) -> None:
        if isinstance(info.exc_value, Terminated):
            self._redelivering = True  # delivered again from another thread, once this hook has returned
            main = threading.main_thread().ident
            self._again = threading.Timer(0.02, signal.pthread_kill, args=(main, signal.SIGTERM))
            self._again.start()
            return
        self._previous_hook(info)

    def raise_if_dropped(self) -> None:
        """Raise the :class:`Terminated` that was dropped if the command ended before it was delivered again."""
        if self._redelivering:
            self._again.cancel()
            self._redelivering = False
            raise Terminated()

    def __exit__(self, *exc_info) -> None:
        if self._installed:  # None: a handler set outside Python, which cannot be put back; the default then
            signal.signal(signal.SIGTERM, signal.SIG_DFL if self._previous is None else self._previous)
            sys.unraisablehook = self._previous_hook


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="tactile-manip", description=(
        "Turn a magnetic tactile sensor's coarse readings into depth images, in-hand angles and contact "
        "estimates: simulate or record a sensor, make datasets, train and evaluate models, and run "
        "grasp-and-reorient trials with an FR3 arm, simulated or real."))
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=_Parser)
    for name, (module, help_text) in COMMANDS.items():
        cmd = sub.add_parser(name, help=help_text, description=help_text)
        importlib.import_module(module).add_arguments(cmd)
        cmd.set_defaults(_module=module)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    with _HeldWarnings() as held, _SigtermRaises() as sigterm:
        try:
            status = int(importlib.import_module(args._module).run(args) or 0)
            sys.stdout.flush()  # a closed stdout shows here, not in the interpreter's exit
            sigterm.raise_if_dropped()
            return status
        except BrokenPipeError:  # the reader went away (`tactile-manip params | head -1`): nothing left to say
            _silence_stdout()
            return 141
        except (TactileManipError, ValueError, OSError) as e:
            held.drop()
            return _fail(args.command, error_line(e))
        except ImportError as e:
            line = missing_extra_message(e)
            if line is None:  # one of our own modules failed to import: a bug, keep the traceback
                raise
            held.drop()
            return _fail(args.command, line)
        except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM (Terminated)
            stop = "terminated" if isinstance(e, Terminated) else "interrupted"
            print(f"tactile-manip {args.command}: {stop}", file=sys.stderr)
            return 143 if isinstance(e, Terminated) else 130


def error_line(error: BaseException) -> str:
    """The one-line text of an expected error; OSErrors name their path (``Permission denied: out/x.npz``)."""
    if isinstance(error, OSError) and not isinstance(error, TactileManipError) and error.filename is not None:
        text = f"{error.strerror or type(error).__name__}: {error.filename}"
        if error.filename2 is not None:
            text += f" -> {error.filename2}"
    else:
        text = str(error) or type(error).__name__
    return " ".join(text.split())


def _fail(command: str, line: str) -> int:
    print(f"tactile-manip {command}: error: {line}", file=sys.stderr)
    return 2


def _silence_stdout() -> None:
    # Python flushes stdout again at exit and would print a second BrokenPipeError; point it at /dev/null
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # not a real file (captured in tests)
        pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
