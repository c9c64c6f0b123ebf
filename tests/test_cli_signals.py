"""SIGTERM ends a command with status 143 and its cleanups run, even when the signal lands where Python drops
exceptions (a ``__del__``, a weakref callback, an import lock's cleanup); a second SIGTERM ends it at once."""

from __future__ import annotations

import gc
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from tactile_manip.cli import Terminated, _SigtermRaises


class _SignalsInDel:
    """An object whose ``__del__`` receives SIGTERM: the handler's Terminated is raised inside ``__del__``."""

    def __del__(self):
        signal.raise_signal(signal.SIGTERM)


def _spin(seconds: float = 5.0) -> None:
    """Run Python code (where a pending signal handler runs) for a while."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pass


def test_a_sigterm_in_a_del_still_reaches_the_command():
    reached_after = []
    with pytest.raises(Terminated), _SigtermRaises():
        _SignalsInDel()  # dropped at once: __del__ raises Terminated, which Python would print and forget
        _spin()
        reached_after.append(True)
    assert reached_after == []


def test_a_sigterm_in_a_weakref_callback_still_reaches_the_command():
    import weakref

    class Target:
        pass

    target = Target()
    ref = weakref.ref(target, lambda _: signal.raise_signal(signal.SIGTERM))
    with pytest.raises(Terminated), _SigtermRaises():
        del target
        gc.collect()
        _spin()
    assert ref() is None


def test_other_unraisable_exceptions_go_to_the_previous_hook(monkeypatch):
    seen = []
    monkeypatch.setattr(sys, "unraisablehook", lambda info: seen.append(type(info.exc_value)))

    class Fails:
        def __del__(self):
            raise RuntimeError("in __del__")

    with _SigtermRaises():
        Fails()
    assert seen == [RuntimeError]
    assert sys.unraisablehook is not None and sys.unraisablehook.__name__ == "<lambda>"


def test_the_block_puts_the_handler_and_the_hook_back():
    handler, hook = signal.getsignal(signal.SIGTERM), sys.unraisablehook
    with _SigtermRaises():
        assert signal.getsignal(signal.SIGTERM) is not handler and sys.unraisablehook is not hook
    assert signal.getsignal(signal.SIGTERM) is handler and sys.unraisablehook is hook


def _child(code: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def test_a_second_sigterm_during_cleanup_ends_the_process_at_once():
    proc = _child("""
        import os, signal, sys, time
        from tactile_manip.cli import Terminated, _SigtermRaises
        with _SigtermRaises():
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(5)
            except Terminated:
                print("cleaning up", flush=True)
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(5)
                print("cleanup finished", flush=True)
    """)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGTERM
    assert out.splitlines() == ["cleaning up"]


def test_a_sigterm_dropped_by_python_still_exits_143_from_main():
    proc = _child("""
        import signal, sys, time
        from tactile_manip import cli

        class Drops:
            def __del__(self):
                signal.raise_signal(signal.SIGTERM)

        def run(args):
            Drops()
            busy_until = time.monotonic() + 10.0  # the command works on, however fast the machine
            while time.monotonic() < busy_until:
                pass
            print("ran to the end", flush=True)
            return 0

        import types
        sys.modules["fake_command"] = types.SimpleNamespace(run=run, add_arguments=lambda p: None)
        cli.COMMANDS = {"fake": ("fake_command", "a command that receives SIGTERM inside __del__")}
        sys.exit(cli.main(["fake"]))
    """)
    started = time.monotonic()
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "ran to the end" not in out
    assert "tactile-manip fake: terminated" in err and "Exception ignored" not in err
    assert time.monotonic() - started < 60


def test_a_command_that_ends_before_the_dropped_sigterm_returns_still_exits_143(monkeypatch, capsys):
    import types

    from tactile_manip import cli

    def run(args):
        _SignalsInDel()  # the Terminated is dropped, and the command returns before it is delivered again
        return 0

    monkeypatch.setitem(sys.modules, "fake_command", types.SimpleNamespace(run=run, add_arguments=lambda p: None))
    monkeypatch.setattr(cli, "COMMANDS", {"fake": ("fake_command", "returns at once")})
    assert cli.main(["fake"]) == 143
    assert "tactile-manip fake: terminated" in capsys.readouterr().err
    time.sleep(0.1)  # the cancelled re-delivery never comes: this process is still here
