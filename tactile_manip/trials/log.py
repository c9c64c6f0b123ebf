"""The trial log of a run: an append-only JSONL file that a killed run cannot corrupt, and its reader.

Run directory layout::

    RUN_DIR/
      run.json        written when the log is created, rewritten (atomically) on each resume:
                      {"format": "tactile_manip.trials", "format_version": 1, "record_version": 1,
                       "run_id", "config_hash" (sha256 of the canonical JSON config), "config",
                       "code_version", "started_utc", "resumes": [{"started_utc", "code_version"}, ...]}
      trials.jsonl    one ``TrialRecord.to_dict()`` JSON object per line, in the order the trials finished
      summary*.md / summary*.json / errors*.png / success_vs_tolerance*.png   (``tactile_manip.trials.report``)

``trials.jsonl`` holds records only (no header line), so any JSONL reader (``pandas.read_json(lines=True)``)
reads it as is. Each line is written with one ``write``, flushed and ``os.fsync``ed before ``append`` returns,
so killing the run loses no completed trial; at worst the last line is torn. The reader skips a torn last
line with a warning; :class:`TrialLog` cuts it off when resuming, so the next record starts on a fresh line.

A run directory that already holds a log is only appended to with ``resume=True`` and the same config hash:
records of different configs never mix in one file. A different code version on resume is allowed (a bug fix
between a crash and the resume is common) and is recorded in ``run.json``'s ``resumes``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
import uuid
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tactile_manip.config import config_differences
from tactile_manip.errors import TactileManipError
from tactile_manip.outputs import check_command_folder, claim_folder, fsync_dir, unique_folder
from tactile_manip.trials.record import RECORD_VERSION, TrialRecord

TRIALS_FILE = "trials.jsonl"
RUN_FILE = "run.json"
FORMAT = "tactile_manip.trials"
FORMAT_VERSION = 1


class TrialLogError(TactileManipError, ValueError):
    """A trial log or run directory is missing, malformed, or may not be appended to (the message says why)."""


class TruncatedRecordWarning(UserWarning):
    """The last line of a trial log is incomplete (the run was killed mid-write); it was skipped."""


def config_hash(config: Mapping[str, Any] | Any) -> str:
    """sha256 (hex) of a run config as canonical JSON (sorted keys; see :func:`canonical_config`)."""
    text = json.dumps(canonical_config(config), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def canonical_config(config: Mapping[str, Any] | Any) -> dict[str, Any]:
    """A run config as plain JSON data: a dataclass goes through ``asdict``, tuples become lists, and other
    non-JSON values (paths, enums) their ``str``. Raises ValueError for non-finite numbers or keys JSON
    cannot hold (numbers become strings, as JSON does)."""
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        config = dataclasses.asdict(config)
    if not isinstance(config, Mapping):
        raise ValueError(f"a run config must be a mapping or a dataclass, got {type(config).__name__}")
    try:
        return json.loads(json.dumps(dict(config), default=str, allow_nan=False))
    except (TypeError, ValueError) as e:
        raise ValueError(f"a run config must be JSON-serialisable (finite numbers, str keys): {e}") from e


def run_folder(scene_name: str, out: str | Path | None, *, resume: bool = False) -> Path:
    """The folder of a trials run: ``out``, or a new ``runs/trials/<scene_name>-<UTC time>`` (``-2``, ``-3``, ...
    appended when runs start within the same second).

    Raises:
        ValueError: ``resume`` without ``out`` (there is no run to continue).
    """
    if out:
        return Path(out)
    if resume:
        raise ValueError("--resume needs --out: the run folder to continue")
    return unique_folder(Path("runs") / "trials" / f"{scene_name}-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}")


def trials_path(path: str | Path) -> Path:
    """The ``trials.jsonl`` of ``path`` (a run directory or the file itself); raises TrialLogError if absent."""
    path = Path(path)
    if path.is_dir():
        file = path / TRIALS_FILE
        if not file.is_file():
            raise TrialLogError(f"{path} holds no {TRIALS_FILE}: is it a run directory (made by "
                                f"`tactile-manip trials`)?")
        return file
    if not path.exists():
        raise TrialLogError(f"no run directory or trial log at {path}")
    return path


def read_run_info(run_dir: str | Path) -> dict[str, Any] | None:
    """The run's ``run.json`` as a dict, or None when the directory has none (a hand-made run)."""
    file = Path(run_dir) / RUN_FILE
    if not file.is_file():
        return None
    try:
        info = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise TrialLogError(f"{file} is not a readable run description: {e}") from e
    if not isinstance(info, dict) or info.get("format") != FORMAT:
        raise TrialLogError(f"{file} is not a tactile_manip run description (format {FORMAT!r} expected)")
    return info


def read_trials(path: str | Path) -> list[TrialRecord]:
    """Every record of a trial log, in file order.

    Args:
        path: a run directory or its ``trials.jsonl``.

    Returns:
        The records (an empty list for an empty log). Blank lines are ignored. A last line that is not valid
        JSON (torn by a kill mid-write) is skipped with a :class:`TruncatedRecordWarning`.

    Raises:
        TrialLogError: the file is missing, or a line before the last is not JSON, or any line is not a trial
            record of a version this code reads; the message names the file and the line number.
    """
    file = trials_path(path)
    try:
        lines = file.read_bytes().split(b"\n")
    except OSError as e:
        raise TrialLogError(f"cannot read {file}: {e}") from e
    numbered = [(i + 1, line) for i, line in enumerate(lines) if line.strip()]
    records = []
    for k, (lineno, line) in enumerate(numbered):
        try:
            d = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            if k == len(numbered) - 1:
                warnings.warn(f"{file}:{lineno}: skipped an incomplete last record (the run was probably "
                              f"killed while writing it): {e}", TruncatedRecordWarning, stacklevel=2)
                break
            raise TrialLogError(f"{file}:{lineno}: not a JSON line ({e}); the log is corrupt in the middle: "
                                f"fix or remove that line") from e
        records.append(_record_from(d, file, lineno))
    return records


def completed_keys(path: str | Path) -> set[tuple[int, str]]:
    """The (trial, method) pairs already logged at ``path`` (run directory or file); empty when there is none.

    Every logged record counts as completed, whatever its outcome: re-running a failed trial would change the
    sample. A torn last line does not count (that trial is run again).
    """
    path = Path(path)
    if not (path / TRIALS_FILE if path.is_dir() else path).exists():
        return set()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TruncatedRecordWarning)
        return {(r.trial, r.method) for r in read_trials(path)}


def _record_from(d: Any, file: Path, lineno: int) -> TrialRecord:
    if not isinstance(d, dict):
        raise TrialLogError(f"{file}:{lineno}: expected a JSON object (a trial record), got {type(d).__name__}")
    version = d.get("version", RECORD_VERSION)
    if not isinstance(version, int) or version > RECORD_VERSION:
        raise TrialLogError(f"{file}:{lineno}: trial record version {version!r} is newer than this code reads "
                            f"({RECORD_VERSION}); upgrade tactile_manip")
    try:
        return TrialRecord.from_dict(d)
    except (TypeError, ValueError) as e:
        raise TrialLogError(f"{file}:{lineno}: not a valid trial record: {e}") from e


class TrialLog:
    """Append-only writer of ``RUN_DIR/trials.jsonl`` (see the module docstring for the layout).

    The constructor does no I/O; :meth:`open` (or ``with``) creates or checks the run directory. Each
    :meth:`append` returns after the line is on disk (flush + fsync). The file is locked (``flock``) while
    open, so a second writer on the same run fails instead of interleaving lines.

    Args:
        run_dir: the run directory (created if missing).
        config: the run's config, JSON-serialisable (a mapping or a dataclass); its hash identifies the run.
        resume: append to an existing log of the same config instead of refusing.
        run_id: id of a new run (default: UTC time + random suffix); ignored on resume (the run keeps its id).
        code_version: recorded in ``run.json`` (default: ``tactile_manip.version.code_version()``).
    """

    def __init__(self, run_dir: str | Path, *, config: Mapping[str, Any] | Any, resume: bool = False,
                 run_id: str | None = None, code_version: str | None = None) -> None:
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / TRIALS_FILE
        self.config = canonical_config(config)
        self.config_hash = config_hash(self.config)
        self.resume = resume
        self._run_id = run_id
        self._code_version = code_version
        self.run_info: dict[str, Any] | None = None
        self.completed: set[tuple[int, str]] = set()
        self._file = None

    @property
    def is_open(self) -> bool:
        return self._file is not None

    def open(self) -> TrialLog:
        """Create the run directory and files, or check them and prepare to append when resuming.

        Raises:
            TrialLogError: the directory already holds a log and ``resume`` is False; or ``resume`` is True
                and the log was made with another config, or has no ``run.json``; or another process has it.
        """
        if self.is_open:
            return self
        version = self._code_version if self._code_version is not None else _code_version()
        now = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        existing = read_run_info(self.run_dir)
        if existing is None and self.path.exists() and self.path.stat().st_size > 0:
            raise TrialLogError(f"{self.path} exists without {RUN_FILE}: cannot tell which config made it; "
                                f"use a new run directory")
        if existing is None:
            # a new run: into a folder trials made (or a new one), never over files it did not write
            check_command_folder(self.run_dir, "trials", (TRIALS_FILE, RUN_FILE), force=False,
                                 hint="pass --resume to continue that run, or give another --out")
            info = {"format": FORMAT, "format_version": FORMAT_VERSION, "record_version": RECORD_VERSION,
                    "run_id": self._run_id or f"{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}-"
                                             f"{uuid.uuid4().hex[:6]}",
                    "config_hash": self.config_hash, "config": self.config, "code_version": version,
                    "started_utc": now, "resumes": []}
        else:
            info = self._check_resume(existing)
            info = {**info, "resumes": [*info.get("resumes", []), {"started_utc": now, "code_version": version}]}
        claim_folder(self.run_dir, "trials")
        self._file = _open_locked(self.path)
        try:
            self._repair_tail()
            self.completed = completed_keys(self.path)
            _write_json_atomic(self.run_dir / RUN_FILE, info)
        except BaseException:
            self.close()
            raise
        self.run_info = info
        return self

    def append(self, record: TrialRecord) -> None:
        """Write one record as a line and return once it is on disk.

        Raises:
            TrialLogError: the log is not open, or (trial, method) is already logged in this run.
        """
        if self._file is None:
            raise TrialLogError("the trial log is not open: use `with TrialLog(...) as log` or call open()")
        key = (record.trial, record.method)
        if key in self.completed:
            raise TrialLogError(f"trial {record.trial} of method {record.method!r} is already in {self.path}; "
                                f"skip the keys in `log.completed` when resuming")
        try:
            line = json.dumps(record.to_dict(), default=_json_default) + "\n"
        except (TypeError, ValueError) as e:
            raise TrialLogError(f"trial {record.trial} of method {record.method!r} cannot be logged: {e}") from e
        self._file.write(line.encode("utf-8"))  # one write per record: a kill tears at most this line
        self._file.flush()
        os.fsync(self._file.fileno())
        self.completed.add(key)

    def close(self) -> None:
        """Close the file (records are already on disk); safe to call twice."""
        if self._file is not None:
            self._file.close()  # also releases the flock
            self._file = None

    def __enter__(self) -> TrialLog:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check_resume(self, existing: dict[str, Any]) -> dict[str, Any]:
        if not self.resume:
            raise TrialLogError(f"{self.run_dir} already holds run {existing.get('run_id')!r}; resume it "
                                f"(resume=True, `--resume`) or choose a new run directory")
        if existing.get("config_hash") != self.config_hash:
            differences = config_differences(existing.get("config") or {}, self.config)
            raise TrialLogError(f"cannot resume {self.run_dir}: it was run with another config (hash "
                                f"{str(existing.get('config_hash'))[:12]}, now {self.config_hash[:12]}; "
                                f"{'; '.join(differences) or 'same values, other form'}); "
                                f"use a new run directory for the new config")
        return existing

    def _repair_tail(self) -> None:
        """Cut a torn last line (or end a complete one) so the next record starts on its own line."""
        f = self._file
        f.seek(0)
        tail = f.read()  # a log is small (about 1 kB per trial); a torn line may be any length
        size = len(tail)
        if size == 0:
            return
        if tail.endswith(b"\n"):
            return
        start = tail.rfind(b"\n") + 1
        fragment = tail[start:]
        try:
            json.loads(fragment)
            f.write(b"\n")  # a complete record that only lacks its newline: keep it
        except (json.JSONDecodeError, UnicodeDecodeError):
            warnings.warn(f"{self.path}: removed an incomplete last record ({len(fragment)} bytes) before "
                          f"resuming", TruncatedRecordWarning, stacklevel=3)
            f.truncate(size - len(fragment))
        f.flush()
        os.fsync(f.fileno())


def _json_default(obj: Any) -> Any:
    """numpy scalars and arrays (``tolist``) in ``extra`` or ``timings_s`` become plain JSON values."""
    if hasattr(obj, "tolist"):
        return obj.tolist()
    raise TypeError(f"{type(obj).__name__} is not JSON-serialisable")


def _open_locked(path: Path):
    """Open ``path`` for appending (binary), holding an exclusive advisory lock where the OS has flock."""
    f = open(path, "a+b")  # noqa: SIM115 - closed by TrialLog.close()
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: no lock
        return f
    try:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as e:
        f.close()
        raise TrialLogError(f"{path} is being written by another process; wait for it or use a new run "
                            f"directory") from e
    fsync_dir(path.parent)
    return f


def _write_json_atomic(path: Path, obj: Any) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(obj, f, indent=2)
        f.write("\n")
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    fsync_dir(path.parent)


def _code_version() -> str:
    from tactile_manip.version import code_version

    return code_version()
