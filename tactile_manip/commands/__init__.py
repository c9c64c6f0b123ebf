"""One module per ``tactile-manip`` subcommand (``add_arguments(parser)`` and ``run(args) -> int``).

Shared here: :func:`check_report_folder`, the check every command that writes a folder of named files makes
before its work starts.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path


def check_report_folder(out: str | Path, files: Sequence[str], *, force: bool,
                        hint: str = "pass --force to replace them, or give another --out") -> Path:
    """Return ``out`` after checking it is a writable folder that holds none of ``files`` (unless ``force``).

    Raises:
        OutputPathError: ``out`` is a file or cannot be written into, or it holds some of ``files`` (an
            earlier run's) and ``force`` is False; ``hint`` says what to do then.
    """
    from tactile_manip.outputs import OutputPathError, check_output_dir

    out = check_output_dir(out)
    held = [name for name in files if (out / name).exists()]
    if held and not force:
        raise OutputPathError(f"{out} already holds {', '.join(held)} of an earlier run: {hint}")
    return out
