"""``tactile-manip export SOURCE --format F --out OUT``: a source's episodes through one writer, atomically.

Writers are looked up by format name in :data:`WRITERS` (``"module:function"``, imported when chosen). Each
takes ``(episodes, out, *, ros2=False)`` and returns a dict of what it wrote; one that also takes
``source_info`` gets the source's facts (calibration, run config, depth model) for its own metadata.

The output appears whole or not at all: the writer fills a temporary sibling of ``OUT`` (a hidden
``.NAME.tmp-PID-HEX`` folder, or ``.NAME.tmp-PID-HEX.rrd`` file) that is renamed to ``OUT`` at the end; on any
failure (SIGTERM and Ctrl-C included) the temporary is removed and ``OUT`` is as it was. What an export killed
outright left beside ``OUT`` (a temporary, or an earlier output moved aside) is removed at the next export to
``OUT`` once its process is gone.

Only what export itself wrote is ever replaced: ``OUT`` must not be the source, lie inside it or hold it, and an
existing ``OUT`` is replaced (with ``force``, once the new output is complete) only when it is an earlier export
of the same format (:data:`EARLIER_OUTPUTS`); anything else is refused, with or without ``force``.
"""

from __future__ import annotations

import importlib
import inspect
import json
import os
import re
import shutil
import struct
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tactile_manip.extras import require
from tactile_manip.interop.sources import Source, read_source
from tactile_manip.outputs import OutputPathError, check_apart, check_writable_parent, fsync_dir

# format -> writer "module:function" (OUT is a folder for lerobot, a file for the others)
WRITERS: dict[str, str] = {
    "lerobot": "tactile_manip.interop.lerobot:write_lerobot",
    "rrd": "tactile_manip.interop.rerun_export:write_rrd",
    "mcap": "tactile_manip.interop.mcap_export:write_mcap",
}
# the optional packages each writer needs, checked before anything is read (each names its extra when missing)
WRITER_PACKAGES: dict[str, tuple[str, ...]] = {"lerobot": ("pyarrow", "pandas"), "rrd": ("rerun",), "mcap": ("mcap",)}


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
    for package in WRITER_PACKAGES.get(fmt, ()):
        require(package, f"export --format {fmt}")
    return getattr(module, func_name)


def export_source(source: str | Path, out: str | Path, *, fmt: str, force: bool = False, ros2: bool = False,
                  depth_model: str | None = None, progress: Callable[[str], None] | None = None) -> ExportResult:
    """Read ``source`` (a trial run folder, a recording or a pair log) and write it as ``fmt`` to ``out``.

    Args:
        depth_model: reconstruct each frame's depth with this model (an ``.onnx`` path, "bilinear" or
            "bicubic") and include it.
        progress: told one line per stage.

    Raises:
        OutputPathError: ``out`` is, holds or lies inside the source; it exists and is not an earlier export of
            ``fmt``; it exists without ``force``; or its folder cannot be written.
        SourceError: the source is none of the three or holds nothing intact.
        ValueError: an unknown format, or a writer that is not installed.
    """
    say = progress or (lambda line: None)
    out = Path(out)
    writer = load_writer(fmt)  # before any work: a missing writer fails at once
    check_target(source, out, fmt=fmt, force=force)
    check_writable_parent(out)
    for line in remove_stale_temporaries(out):
        say(line)
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


def check_target(source: str | Path, out: Path, *, fmt: str, force: bool) -> None:
    """Refuse an ``out`` that export must not write: the source, a path inside it or a folder holding it, and an
    existing path that is not an earlier export of ``fmt`` (whatever ``force``), or any existing path without
    ``force``. Reads only ``out``'s first bytes: made before the source is read.

    Raises:
        OutputPathError: the line names ``out`` and why it is refused.
    """
    check_apart(out, [("the source", source)])
    if not (out.exists() or out.is_symlink()):
        return
    what, reason_not_ours = EARLIER_OUTPUTS.get(fmt, (f"a {fmt} output", _unknown_output))
    why = reason_not_ours(out)
    if why is not None:
        raise OutputPathError(f"{out} is not {what} written by tactile-manip export ({why}); refusing to replace "
                              "it: choose another --out or remove it yourself")
    if not force:
        raise OutputPathError(f"{out} exists; pass --force to replace it")


# what the LeRobot writer puts in OUT, and the marker it writes (meta/tactile.json "format")
LEROBOT_ENTRIES = frozenset({"meta", "data"})
LEROBOT_MARKER = ("meta/tactile.json", "tactile_manip.lerobot")
MCAP_MAGIC = b"\x89MCAP0\r\n"
MCAP_LIBRARY = "tactile_manip "  # followed by the version (mcap_export.write_mcap)
HEAD_BYTES = 1 << 16  # how much of a file the checks read


def _not_our_lerobot(out: Path) -> str | None:
    """Why the folder ``out`` is not a dataset of :func:`~tactile_manip.interop.lerobot.write_lerobot`, or None."""
    if not out.is_dir():
        return "it is not a folder" if out.exists() else "it is a dangling symlink"
    marker, fmt = LEROBOT_MARKER
    try:
        ours = json.loads((out / marker).read_text(encoding="utf-8")).get("format") == fmt
    except (OSError, ValueError, AttributeError):  # missing, unreadable, not JSON, not an object
        ours = False
    if not ours:
        return f"it has no {marker} of format {fmt}"
    others = sorted(p.name for p in out.iterdir() if p.name not in LEROBOT_ENTRIES)
    if others:
        listed = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
        return f"it also holds {listed}, which export did not write"
    return None


def _head(out: Path) -> bytes | str:
    """The first bytes of the file ``out``, or why it has none to read."""
    if out.is_dir():
        return "it is a folder"
    try:
        with open(out, "rb") as f:
            return f.read(HEAD_BYTES)
    except OSError as e:
        return f"it cannot be read: {e.strerror or type(e).__name__}"


def _not_our_mcap(out: Path) -> str | None:
    """Why ``out`` is not an MCAP file of :func:`~tactile_manip.interop.mcap_export.write_mcap`, or None."""
    head = _head(out)
    if isinstance(head, str):
        return head
    if not head.startswith(MCAP_MAGIC) or head[8:9] != b"\x01":  # the magic, then the Header record (op 0x01)
        return "it does not start as an MCAP file"
    try:
        at = 8 + 1 + 8  # magic, opcode, record length
        at += 4 + struct.unpack_from("<I", head, at)[0]  # the profile string
        size = struct.unpack_from("<I", head, at)[0]
        library = head[at + 4:at + 4 + size].decode("utf-8")
    except (struct.error, UnicodeDecodeError):
        return "its MCAP header is damaged"
    if not library.startswith(MCAP_LIBRARY):
        return f"its MCAP header names the library {library!r}"
    return None


def _not_our_rrd(out: Path) -> str | None:
    """Why ``out`` is not a Rerun file of tactile_manip (Rerun's magic, then our application id), or None."""
    from tactile_manip.interop.rerun_log import APPLICATION_ID

    head = _head(out)
    if isinstance(head, str):
        return head
    if not (head[:3] == b"RRF" and head[3:4].isdigit()):
        return "it does not start as a Rerun file"
    if APPLICATION_ID.encode() not in head:  # the first message is the recording's info, with its application id
        return f"its recording is not of the application {APPLICATION_ID}"
    return None


def _unknown_output(out: Path) -> str:
    return "export cannot tell its own outputs of this format"


# format -> (what an earlier output of it is, why a path is not one: None when it is)
EARLIER_OUTPUTS: dict[str, tuple[str, Callable[[Path], str | None]]] = {
    "lerobot": ("a LeRobot dataset", _not_our_lerobot),
    "mcap": ("an MCAP file", _not_our_mcap),
    "rrd": ("a Rerun file", _not_our_rrd),
}


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


def _temporary_names(out: Path) -> re.Pattern:
    """The names :func:`write_atomically` gives its temporary and an output it moved aside; the group ``tmp`` or
    ``old`` holds the pid of the export that made it."""
    return re.compile(rf"\.{re.escape(out.stem)}\.tmp-(?P<tmp>\d{{1,10}})-[0-9a-f]{{8}}{re.escape(out.suffix)}"
                      rf"|\.{re.escape(out.name)}\.old-(?P<old>\d{{1,10}})-[0-9a-f]{{8}}")


def remove_stale_temporaries(out: Path) -> list[str]:
    """Remove what exports to ``out`` that were killed outright left beside it; one line per path removed or kept.

    Only names of :func:`write_atomically`'s own pattern whose process is gone are touched. An earlier output
    moved aside while ``out`` is missing (the export was killed between the two renames) is kept and named: it
    is the only copy of that output.
    """
    pattern = _temporary_names(out)
    try:
        found = [(p, m) for p in out.parent.iterdir() if (m := pattern.fullmatch(p.name))]
    except OSError:  # no such folder yet: nothing to clean
        return []
    lines = []
    for path, match in found:
        if _process_alive(int(match["tmp"] or match["old"])):
            continue
        if match["old"] and not (out.exists() or out.is_symlink()):
            lines.append(f"kept {path}: an earlier {out.name} that an export stopped while replacing it; rename "
                         f"it to {out.name} to keep it")
            continue
        _remove(path)
        lines.append(f"removed {path}, left by an export that was killed")
    return lines


def _process_alive(pid: int) -> bool:
    """False only when no process has ``pid`` (an unknown answer counts as alive: its files are kept)."""
    if os.name != "posix":  # elsewhere os.kill(pid, 0) would end the process, not probe it
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (OSError, OverflowError):  # another user's process, or a pid out of range
        return True
    return True
