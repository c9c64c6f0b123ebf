"""Checks on the files and folders a command will write, made before any long work starts.

A command that would fail on its output only after minutes of simulation, or that would silently replace a
file it did not create, calls one of these first. Each raises :class:`OutputPathError` (one line at the CLI)
that names the path and what to do.

A command that writes a folder of named files owns it: :func:`claim_folder` creates it with an owner file
(``.tactile-manip.json``, naming the command) when the command starts writing, and :func:`check_command_folder`
refuses, before any work, a folder the command does not own: one that holds anything without that mark, or one
another command marked. ``--force`` then replaces only the command's own files in a folder it owns.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path

from tactile_manip.errors import TactileManipError


class OutputPathError(TactileManipError, OSError):
    """An output path cannot be written, or holds something that must not be replaced without ``--force``."""


def check_output_file(path: str | Path, *, force: bool = False, ours: Callable[[Path], bool] | None = None,
                      what: str = "file of this command") -> Path:
    """Return ``path`` after checking that a file can be written there.

    ``ours`` (given: ``--force`` replaces only what the same command wrote) says whether an existing file at
    ``path`` is one the command wrote (``what`` names it in the refusal).

    Raises:
        OutputPathError: ``path`` is a directory; it exists and ``force`` is False, or ``force`` is True and
            ``ours`` says it is not the command's; its nearest existing parent is not a directory; or that parent
            cannot be written into (permissions, a read-only file system).
    """
    path = Path(path)
    if path.is_dir():
        raise OutputPathError(f"{path} is a directory; give a file name")
    if (path.exists() or path.is_symlink()) and not force:
        raise OutputPathError(f"{path} exists; pass --force to overwrite it")
    if force and ours is not None and (path.exists() or path.is_symlink()) and not ours(path):
        raise OutputPathError(f"{path} is not a {what}; refusing to replace it, with or without --force: choose "
                              "another output or remove it yourself")
    check_writable_parent(path)
    return path


def check_output_dir(path: str | Path) -> Path:
    """Return ``path`` after checking that it is, or can be created as, a writable directory.

    Raises:
        OutputPathError: ``path`` exists and is not a directory, or it (or its nearest existing parent) cannot
            be written into.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputPathError(f"{path} exists and is not a directory; give a folder")
    if path.is_dir():
        _probe(path, path)
    else:
        check_writable_parent(path)
    return path


def check_report_folder(out: str | Path, files: Sequence[str], *, force: bool,
                        hint: str = "pass --force to replace them, or give another --out") -> Path:
    """Return ``out`` after checking it is a writable folder that holds none of ``files`` (unless ``force``).

    Raises:
        OutputPathError: ``out`` is a file or cannot be written into, or it holds some of ``files`` (an
            earlier run's) and ``force`` is False; ``hint`` says what to do then.
    """
    out = check_output_dir(out)
    held = [name for name in files if (out / name).exists()]
    if held and not force:
        raise OutputPathError(f"{out} already holds {', '.join(held)} of an earlier run: {hint}")
    return out


OWNER_FILE = ".tactile-manip.json"  # names the command that created the folder it sits in


def folder_owner(path: str | Path) -> str | None:
    """The command that created the folder ``path`` (its owner file), or None when it has no readable one."""
    try:
        owner = json.loads((Path(path) / OWNER_FILE).read_text()).get("command")
    except (OSError, ValueError, AttributeError):
        return None
    return owner if isinstance(owner, str) else None


def check_command_folder(out: str | Path, command: str, files: Sequence[str], *, force: bool,
                         also: Sequence[str] = (),
                         hint: str = "pass --force to replace them, or give another --out") -> Path:
    """Return ``out`` after checking that ``command`` may write ``files`` there: ``out`` does not exist yet, is an
    empty folder, or is a folder ``command`` (or one of ``also``) created; and, unless ``force``, holds none of
    ``files`` (an earlier run's).

    Raises:
        OutputPathError: ``out`` is a file or cannot be written into; it holds files without the owner mark
            (with or without ``force``: they are not the command's to replace); another command created it; or
            it holds some of ``files`` and ``force`` is False (``hint`` says what to do then).
    """
    out = check_output_dir(out)
    if out.is_dir():
        owner = folder_owner(out)
        if owner is None:
            held = sorted(p.name for p in out.iterdir())
            if held:
                shown = ", ".join(held[:3]) + (f" and {len(held) - 3} more" if len(held) > 3 else "")
                raise OutputPathError(f"{out} holds files that tactile-manip {command} did not write ({shown}); "
                                      "refusing to write there, with or without --force: give a new or empty folder")
        elif owner != command and owner not in also:
            raise OutputPathError(f"{out} is a folder of tactile-manip {owner}, not of {command}; refusing to write "
                                  "there: give another folder")
    return check_report_folder(out, files, force=force, hint=hint)


def claim_folder(out: str | Path, command: str) -> Path:
    """Create ``out`` (and its parents) as ``command``'s folder, with the owner file; a folder it already owns is
    kept as it is. Call it when the command starts writing, after :func:`check_command_folder`."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    marker = out / OWNER_FILE
    if folder_owner(out) is None:
        tmp = out / f".{OWNER_FILE}.tmp-{os.getpid()}"
        tmp.write_text(json.dumps({"command": command}) + "\n")
        os.replace(tmp, marker)
    return out


def check_apart(out: str | Path, inputs: Iterable[tuple[str, str | Path]], *, option: str = "--out") -> None:
    """Refuse an output that would write over, into or around one of a command's inputs.

    ``inputs`` are ``(label, path)`` pairs, e.g. ``("the source", "run.tmrec")``; paths are compared after
    resolving symlinks (and a hard link to an input counts as the input). Checked with or without ``--force``;
    ``option`` is the output's option, named in the message.

    Raises:
        OutputPathError: ``out`` is an input, lies inside an input folder, or is a folder holding an input.
    """
    target = Path(out).resolve()
    for label, given in inputs:
        source = Path(given).resolve()
        if target == source or _same_file(target, source):
            raise OutputPathError(f"{out} is {label} {given} itself; refusing to write over it: choose another "
                                  f"{option}")
        if target.is_relative_to(source):
            raise OutputPathError(f"{out} is inside {label} {given}; refusing to write there: choose an {option} "
                                  "outside it")
        if source.is_relative_to(target):
            raise OutputPathError(f"{out} holds {label} {given}; refusing to replace it: choose another {option}")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def check_writable_parent(path: str | Path) -> Path:
    """The nearest existing ancestor of ``path``, after checking that files can be created in it."""
    path = Path(path)
    ancestor = path.absolute().parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise OutputPathError(f"cannot write {path}: {ancestor} is not a directory")
    _probe(ancestor, path)
    return ancestor


def _probe(folder: Path, target: Path) -> None:
    # creating a file is the only check that also holds for root and for read-only mounts (os.access is not)
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".tactile_manip-probe-"):
            pass
    except OSError as e:
        raise OutputPathError(f"cannot write {target}: cannot create files in {folder} ({e.strerror})") from e


@contextlib.contextmanager
def unfinished(path: str | Path) -> Iterator[Path]:
    """The block writes ``path`` (a temporary name, renamed into place at its end); should the block fail, or be
    interrupted, ``path`` is removed, so no half-written file is left for a loader to find."""
    path = Path(path)
    try:
        yield path
    except BaseException:
        path.unlink(missing_ok=True)
        raise


def unique_folder(path: str | Path) -> Path:
    """``path`` when nothing exists there, else the first free ``path-2``, ``path-3``, ... (timestamped run
    folders made within the same second stay apart)."""
    path = Path(path)
    candidate, n = path, 1
    while candidate.exists() or candidate.is_symlink():
        n += 1
        candidate = path.with_name(f"{path.name}-{n}")
    return candidate


def fsync_dir(path: str | Path) -> None:
    """Make a new or renamed entry of the directory ``path`` durable (a no-op where directories cannot be
    opened, e.g. Windows)."""
    import os

    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # pragma: no cover - not POSIX
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)
