"""Progress of long work: a bar on a terminal, a few plain lines in a log, nothing when asked to be quiet.

A carriage-return progress bar written to a file or a pipe fills a log with thousands of half-lines. Every
command therefore makes its bars with :func:`progress_bar`: on a terminal it is a tqdm bar; written anywhere
else it prints one line when the stage ends (``training contact x5: 300/300 epochs in 95.2 s``), and a line at
most every ``heartbeat_s`` while it runs, so a log of a long job still shows it is alive; with ``quiet`` it
prints nothing.

::

    with progress_bar(total=len(items), desc="simulating", unit="pair", quiet=args.quiet) as bar:
        for item in items:
            ...
            bar.update()
"""

from __future__ import annotations

import sys
import time
from typing import IO, Any

HEARTBEAT_S = 20.0  # at most one line every 20 s while a stage runs, off a terminal: no log silent for long


def progress_bar(*, total: int | None, desc: str, unit: str = "it", quiet: bool = False, initial: int = 0,
                 stream: IO[str] | None = None, heartbeat_s: float = HEARTBEAT_S):
    """A progress display for ``total`` steps of ``desc`` (tqdm's interface: ``update``, ``set_postfix``,
    ``close``, a context manager).

    ``stream`` (default: standard error) decides the form: a tqdm bar where it is a terminal, else
    :class:`StageLines`; ``quiet`` gives :class:`StageLines` that print nothing.
    """
    stream = sys.stderr if stream is None else stream
    if not quiet and _is_terminal(stream):
        from tqdm import tqdm

        return tqdm(total=total, desc=desc, unit=unit, initial=initial, file=stream)
    return StageLines(total=total, desc=desc, unit=unit, initial=initial, stream=None if quiet else stream,
                      heartbeat_s=heartbeat_s)


def _is_terminal(stream: IO[str]) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


class StageLines:
    """A stage's progress as plain lines: one when it ends (steps done, time taken, the last postfix), and one at
    most every ``heartbeat_s`` while it runs; nothing at all with ``stream`` None."""

    def __init__(self, *, total: int | None, desc: str, unit: str = "it", initial: int = 0,
                 stream: IO[str] | None = None, heartbeat_s: float = HEARTBEAT_S) -> None:
        self.total, self.desc, self.unit, self.n = total, desc, unit, initial
        self._stream, self._heartbeat_s = stream, heartbeat_s
        self._t0 = self._last = time.monotonic()
        self._postfix = ""
        self._closed = False

    def update(self, n: int = 1) -> None:
        self.n += n
        now = time.monotonic()
        if self._stream is not None and now - self._last >= self._heartbeat_s:
            self._last = now
            self._write(f"{self._count()}, {now - self._t0:.0f} s so far")

    def set_postfix(self, ordered_dict: dict[str, Any] | None = None, **values: Any) -> None:
        items = {**(ordered_dict or {}), **values}
        self._postfix = ", ".join(f"{k}={v}" for k, v in items.items())

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._stream is not None:
            self._write(f"{self._count()} in {time.monotonic() - self._t0:.1f} s")

    def _count(self) -> str:
        done = f"{self.n}/{self.total}" if self.total is not None else f"{self.n}"
        return f"{done} {self.unit}" + (f" ({self._postfix})" if self._postfix else "")

    def _write(self, text: str) -> None:
        try:
            print(f"{self.desc}: {text}", file=self._stream, flush=True)
        except (OSError, ValueError):  # a closed log stream must not end the work it reports on
            self._stream = None

    def __enter__(self) -> StageLines:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
