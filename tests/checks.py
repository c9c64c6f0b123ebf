"""Assertions and helpers shared by the test layers: the CLI's one-line errors, the estimate contract, Ctrl-C for a
command under test; the torch skip reason.

Import them as ``from checks import ...`` (``tests/`` is on ``sys.path``: see ``pythonpath`` in pyproject.toml).
"""

from __future__ import annotations

import math
from pathlib import Path

# The reference models of the studies (experiments/model_variants/): files the tests read by path.
REFERENCE_MODELS_DIR = Path(__file__).resolve().parents[1] / "experiments" / "model_variants"
REFERENCE_MODELS = ("supermag_fast.onnx", "supermag_robust.onnx", "supermag_compact.onnx")

# The reason every torch-dependent test skips with (``pytest.importorskip("torch", reason=TORCH_MISSING)``);
# tests/conftest.py counts these skips and says so loudly.
TORCH_MISSING = ("torch is not installed: the training, export and model tests need it "
                 "(pip install torch==2.13.0, the CPU build, then pip install -e \".[dev]\")")


def assert_one_line_error(err: str, command: str, *needles: str, program: str = "tactile-manip",
                          after_progress: bool = False) -> str:
    """``err`` (a command's whole stderr) is exactly the CLI's error line for ``command``, ending in one newline:
    ``tactile-manip COMMAND: error: ...``, with no traceback, containing every one of ``needles``.

    ``program=""`` for the task scripts, whose line starts ``SCRIPT.py: error: ``. ``after_progress``: the command
    drew a progress bar on stderr before failing (``train``); the error must then be the last line, and nothing
    before it an error or a traceback. Returns the line (without its newline) so callers can check more of it.
    """
    if after_progress:
        *progress, last = err.splitlines(keepends=True)
        assert not any("error" in p or "Traceback" in p for p in progress), err
        err = last
    assert err.endswith("\n") and err.count("\n") == 1, f"expected exactly one line on stderr, got:\n{err}"
    line = err[:-1]
    assert line.startswith(f"{program} {command}: error: ".lstrip()), line
    assert "Traceback" not in line, line
    for needle in needles:
        assert needle in line, f"{needle!r} not in {line!r}"
    return line


def assert_one_line_message(message: str, *needles: str) -> str:
    """An exception's message fit for the CLI's one line: non-empty, no line break, containing every needle."""
    assert message.strip() and "\n" not in message and "\r" not in message, repr(message)
    for needle in needles:
        assert needle in message, f"{needle!r} not in {message!r}"
    return message


def assert_sane_estimate(est) -> None:
    """The contract of every :class:`~tactile_manip.types.AngleEstimate` (tactile_manip/types.py, pose.py):

    - every number finite (never NaN, whatever the image or reading);
    - confidence in [0, 1]; angle wrapped to (-pi/2, pi/2];
    - defined: ``reason`` is "";
    - undefined (empty, tiny or isotropic contact, no contact field): ``reason`` says why, and the estimate
      carries angle 0.0 and confidence 0.0, so a caller that ignores ``defined`` cannot act on it.
    """
    values = (est.angle_rad, est.confidence, est.area_mm2, *est.centroid_mm)
    assert all(math.isfinite(v) for v in values), est
    assert 0.0 <= est.confidence <= 1.0, est
    assert -math.pi / 2 < est.angle_rad <= math.pi / 2, est
    if est.defined:
        assert est.reason == "", est
    else:
        assert est.reason, est
        assert est.angle_rad == 0.0 and est.confidence == 0.0, est


def ctrl_c_as_in_a_terminal() -> None:
    """``preexec_fn`` of a command a test sends Ctrl-C: a test run started in the background (``cmd &`` in a
    script) hands its children SIGINT ignored, and Python then never raises KeyboardInterrupt; this gives the
    command SIGINT as a terminal would."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
