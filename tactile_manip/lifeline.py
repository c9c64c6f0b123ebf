"""What a command leaves running or on disk goes when the command goes, however it goes: SIGKILL included.

A command cleans up after itself in ``finally`` blocks, which Ctrl-C and SIGTERM reach but SIGKILL (or a crash
of the interpreter) does not. For what must not outlive it (a server it started, a link it made), the command
starts a :class:`Lifeline`: a small watchdog process, in a session of its own, that holds the read end of a pipe
from the command. When the pipe closes without a word (the command died), the watchdog stops the process groups
it was given (SIGTERM, then SIGKILL after ``grace_s``) and removes the links it was given, each only while it
still points where the command made it point. :meth:`Lifeline.release` (the command cleaned up itself) tells it
to go without doing anything.

::

    with Lifeline(groups=[server.pid], links=[(link_path, pty_path)]):
        ...  # the server and the link go with this process
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

RELEASE = b"release\n"  # what the command writes when it cleaned up itself
GRACE_S = 3.0  # a group asked to stop is killed after this long

# The watchdog: its argument is {"groups": [pgid, ...], "links": [[path, target], ...], "grace_s": s}. It waits for
# its stdin to close; unless the command wrote RELEASE first, it stops the groups and removes the links.
_WATCHDOG = r"""
import json, os, signal, sys, time

spec = json.loads(sys.argv[1])
said = sys.stdin.buffer.read()
if said.startswith(b"release"):
    sys.exit(0)

def alive(group):
    try:
        os.killpg(group, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True

groups = [g for g in spec["groups"] if alive(g)]
for g in groups:
    try:
        os.killpg(g, signal.SIGTERM)
    except OSError:
        pass
deadline = time.monotonic() + spec["grace_s"]
while groups and time.monotonic() < deadline:
    time.sleep(0.05)
    groups = [g for g in groups if alive(g)]
for g in groups:
    try:
        os.killpg(g, signal.SIGKILL)
    except OSError:
        pass
for path, target in spec["links"]:
    try:
        if os.path.islink(path) and os.readlink(path) == target:
            os.unlink(path)
    except OSError:
        pass
"""


class Lifeline:
    """A watchdog that stops ``groups`` (process group ids) and removes ``links`` (``(path, target)``: a symlink
    at ``path`` while it points to ``target``) when this process dies without calling :meth:`release`.

    POSIX only; elsewhere (no process groups) it does nothing. The constructor starts the watchdog (one short
    Python process, asleep on a pipe); a context manager releases it on exit, as :meth:`release` does.
    """

    def __init__(self, *, groups: Sequence[int] = (), links: Sequence[tuple[str | Path, str | Path]] = (),
                 grace_s: float = GRACE_S) -> None:
        self._proc: subprocess.Popen | None = None
        if os.name != "posix":  # pragma: no cover - no process groups to stop
            return
        spec = {"groups": [int(g) for g in groups], "links": [[str(p), str(t)] for p, t in links],
                "grace_s": float(grace_s)}
        # a session of its own: a terminal's Ctrl-C to the command's group does not stop the watchdog first; the
        # pipe's write end is not inherited by other children, so its closing means this process is gone
        self._proc = subprocess.Popen([sys.executable, "-c", _WATCHDOG, json.dumps(spec)], stdin=subprocess.PIPE,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)

    @property
    def pid(self) -> int | None:
        """The watchdog's process id (None where there is none)."""
        return None if self._proc is None else self._proc.pid

    def release(self) -> None:
        """The command cleaned up itself: the watchdog goes without touching anything. Idempotent."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            proc.stdin.write(RELEASE)
            proc.stdin.close()
        except OSError:  # it is gone already
            pass
        try:
            proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:  # pragma: no cover - it only has to read a pipe and exit
            proc.kill()

    def __enter__(self) -> Lifeline:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
