"""``tactile-manip export SOURCE --format F --out OUT``: a source's episodes through one writer, atomically.

Writers are looked up by format name in :data:`WRITERS` (``"module:function"``, imported when chosen). Each
takes ``(episodes, out, *, ros2=False)`` and returns a dict of what it wrote; one that also takes
``source_info`` gets the source's facts (calibration, run config, depth model) for its own metadata.

The output appears whole or not at all: the writer fills a temporary sibling of ``OUT`` (a hidden
``.NAME.tmp-*`` folder, or ``.NAME.tmp-*.rrd`` file) that is renamed to ``OUT`` at the end; on any failure the temporary is
removed and ``OUT`` is as it was. An existing ``OUT`` is refused unless ``force`` (then it is replaced only
after the new output is complete).
"""

from __future__ import annotations

import importlib
import inspect
import os
import shutil
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tactile_manip.interop.sources import Source, read_source
from tactile_manip.outputs import OutputPathError, check_writable_parent, fsync_dir

# format -> writer "module:function" (OUT is a folder for lerobot, a file for the others)
WRITERS: dict[str, str] = {
    "lerobot": "tactile_manip.interop.lerobot:write_lerobot",
    "rrd": "tactile_manip.interop.rerun_export:write_rrd",
    "mcap": "tactile_manip.interop.mcap_export:write_mcap",
}


@dataclass
class ExportResult:
    """What :func:`export_source` did: the output, the source read, and the writer's own summary."""

    out: Path
    format: str
    source: Source
    written: dict[str, Any] = field(default_factory=dict)


def load_writer(fmt: str) -> Callable[..., dict]:
    """The writer function of format ``fmt``.

    Raises:
        ValueError: an unknown format, or one whose writer is not part of this installation.
    """
    if fmt not in WRITERS:
        raise ValueError(f"--format: unknown format {fmt!r}; choose one of {sorted(WRITERS)}")
    module_name, func_name = WRITERS[fmt].split(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        if e.name != module_name:  # the writer exists but a package it needs does not: the extra's message
            raise
        raise ValueError(f"--format {fmt}: this installation has no {fmt} writer ({module_name} is missing)") from None
    return getattr(module, func_name)


def export_source(source: str | Path, out: str | Path, *, fmt: str, force: bool = False, ros2: bool = False,
                  depth_model: str | None = None, progress: Callable[[str], None] | None = None) -> ExportResult:
    """Read ``source`` (a trial run folder, a recording or a pair log) and write it as ``fmt`` to ``out``.

    Args:
        depth_model: reconstruct each frame's depth with this model (an ``.onnx`` path, "bilinear" or
            "bicubic") and include it.
        progress: told one line per stage.

    Raises:
        OutputPathError: ``out`` exists without ``force``, or its folder cannot be written.
        SourceError: the source is none of the three or holds nothing intact.
        ValueError: an unknown format, or a writer that is not installed.
    """
    say = progress or (lambda line: None)
    out = Path(out)
    if (out.exists() or out.is_symlink()) and not force:
        raise OutputPathError(f"{out} exists; pass --force to replace it")
    check_writable_parent(out)
    writer = load_writer(fmt)  # before any work: a missing writer fails at once
    src = read_source(source)
    say(f"read {src.kind} {src.path}: {len(src.episodes)} episodes, {src.frames} frames")
    info = {"kind": src.kind, "path": str(src.path), **src.meta, "skipped": list(src.skipped)}
    if depth_model is not None:
        from tactile_manip.interop.depth import add_depth

        info["depth_model"] = add_depth(src.episodes, depth_model)
        say(f"reconstructed depth with {depth_model}")
    kwargs: dict[str, Any] = {"ros2": ros2}
    if "source_info" in inspect.signature(writer).parameters:
        kwargs["source_info"] = info
    written = write_atomically(out, lambda tmp: writer(src.episodes, tmp, **kwargs))
    return ExportResult(out, fmt, src, written or {})


def write_atomically(out: Path, write: Callable[[Path], Any]) -> Any:
    """Call ``write(tmp)`` on a fresh temporary sibling path of ``out``, then rename it to ``out``.

    ``write`` creates ``tmp`` (a file or a folder). A failure removes ``tmp`` and leaves ``out`` untouched; an
    existing ``out`` is replaced only after ``write`` returned (a folder is moved aside, then removed).
    """
    out = Path(out)
    tag = f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
    tmp = out.with_name(f".{out.stem}.tmp-{tag}{out.suffix}")  # the suffix stays: a writer may look at it
    try:
        result = write(tmp)
        if not (tmp.exists() or tmp.is_symlink()):
            raise OSError(f"the writer made nothing at {tmp}")
        _replace(tmp, out, tag)
    except BaseException:
        _remove(tmp)
        raise
    fsync_dir(out.parent)
    return result


def _replace(tmp: Path, out: Path, tag: str) -> None:
    if tmp.is_dir() and (out.exists() or out.is_symlink()):
        aside = out.with_name(f".{out.name}.old-{tag}")
        os.replace(out, aside)
        try:
            os.replace(tmp, out)
        except BaseException:
            os.replace(aside, out)
            raise
        _remove(aside)
    elif out.is_dir() and not out.is_symlink():  # a file replacing a folder (--force)
        aside = out.with_name(f".{out.name}.old-{tag}")
        os.replace(out, aside)
        os.replace(tmp, out)
        _remove(aside)
    else:
        os.replace(tmp, out)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    elif path.exists() or path.is_symlink():
        path.unlink(missing_ok=True)
