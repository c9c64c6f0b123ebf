"""The append-only framed file under recordings and pair logs: survives a crash up to the last fsync.

Layout: a magic line, one JSON header line, then records ``tag (2 bytes) | payload length | t_host_s f64 |
payload | crc32 u32`` (little-endian; the CRC-32 covers tag, length, time and payload). The length field's
width is the format's (``RECORD`` struct). The writer flushes and ``fsync``s at least every ``sync_every_s``
while records keep coming and on close.

Readers go through :func:`scan_records`: a damaged record in the middle (a flipped byte, a bad sector) is
skipped by searching for the next intact one, as the serial decoder resyncs on the wire, and counted; only
bytes after the last intact record are a torn tail.
"""

from __future__ import annotations

import json
import os
import struct
import time
import zlib
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.errors import RecordingError
from tactile_manip.version import code_version

CRC32 = struct.Struct("<I")
TAG_EVENT = b"EV"


def json_default(obj: Any) -> Any:
    """JSON for numpy scalars and arrays and paths (``json.dumps(..., default=json_default)``)."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


class FramedWriter:
    """Create ``path`` (replacing it) with ``magic`` and a header, and append CRC-framed records to it.

    Args:
        path: file to create.
        magic: first line, e.g. ``b"tactile_manip recording\\n"``.
        header: JSON-serialisable metadata; ``format_version``, ``code_version`` and ``created_utc`` are added.
        record: struct of the record head ``(tag, payload length, t_host_s)``.
        sync_every_s: flush and fsync at least this often when records keep coming, s (in (0, 1]).
        sync_on_write: check the sync interval after every record (otherwise call :meth:`maybe_sync`).
        sync_header: fsync the header at once (off: the first sync is the first interval's or the close's).

    A ``code_version`` in ``header`` is kept (a writer of many files computes it once: it runs git).
    """

    def __init__(self, path: str | Path, magic: bytes, header: dict[str, Any], record: struct.Struct, *,
                 sync_every_s: float = 0.5, sync_on_write: bool = True, sync_header: bool = True) -> None:
        if not 0 < sync_every_s <= 1.0:
            raise ValueError(f"sync_every_s must be in (0, 1], got {sync_every_s}")
        self.path = Path(path)
        self.sync_every_s = sync_every_s
        self._record, self._sync_on_write = record, sync_on_write
        head = {"code_version": header["code_version"] if "code_version" in header else code_version(),
                "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), **header}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._file.write(magic + json.dumps(head, default=json_default).encode() + b"\n")
        self._last_sync = time.monotonic()
        if sync_header:
            self.sync()

    def write_event(self, t_host_s: float, event: dict[str, Any]) -> None:
        """A JSON event record (tag ``EV``)."""
        self.write_record(TAG_EVENT, t_host_s, json.dumps(event, default=json_default).encode())

    def write_record(self, tag: bytes, t_host_s: float, payload: bytes) -> None:
        head = self._record.pack(tag, len(payload), t_host_s)
        self._file.write(head + payload + CRC32.pack(zlib.crc32(payload, zlib.crc32(head))))
        if self._sync_on_write:
            self.maybe_sync()

    def sync(self) -> None:
        """Push everything written so far to the disk."""
        self._file.flush()
        os.fsync(self._file.fileno())
        self._last_sync = time.monotonic()

    def maybe_sync(self) -> None:
        if time.monotonic() - self._last_sync >= self.sync_every_s:
            self.sync()

    def close(self) -> None:
        if not self._file.closed:
            self.sync()
            self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_header(data: bytes, path: Path, magic: bytes, kind: str, format_version: int) -> tuple[dict[str, Any], int]:
    """The JSON header of a framed file's bytes and the offset of its first record.

    Raises:
        RecordingError: not a ``kind`` file (wrong magic), a missing or damaged header, or a newer format.
    """
    if not data.startswith(magic):
        raise RecordingError(f"{path} is not a tactile_manip {kind} (it does not start with {magic!r})")
    end = data.find(b"\n", len(magic))
    try:
        header = json.loads(data[len(magic):end]) if end > 0 else None
    except ValueError:
        header = None
    if not isinstance(header, dict):
        raise RecordingError(f"{path}: the header line is missing or damaged (was the writer killed at once?)")
    if header.get("format_version", 0) > format_version:
        raise RecordingError(f"{path} has {kind} format {header['format_version']}; this tactile_manip reads up "
                             f"to {format_version}: upgrade tactile_manip")
    return header, end + 1


@dataclass
class Scan:
    """What :func:`scan_records` found: the intact records and what it had to skip.

    Attributes:
        records: ``(tag, t_host_s, payload)`` of every intact record, in file order.
        skipped_bytes: bytes between intact records that belong to no intact record (damage in the middle).
        damaged_records: places where damage was skipped (each one or more lost records).
        truncated_bytes: bytes after the last intact record (a crash's torn tail; 0 for a clean file).
        places: ``(byte offset, bytes)`` of each damaged place, in file order (offset -1 where a reader skipped
            an intact record that failed to decode).
    """

    records: list[tuple[bytes, float, bytes]] = field(default_factory=list)
    skipped_bytes: int = 0
    damaged_records: int = 0
    truncated_bytes: int = 0
    places: list[tuple[int, int]] = field(default_factory=list)

    def skip(self, nbytes: int, at: int = -1) -> None:
        """Count one more damaged place of ``nbytes`` at byte offset ``at`` (also used by readers for a record that
        fails to decode, whose offset they do not know: -1)."""
        self.skipped_bytes += nbytes
        self.damaged_records += 1
        self.places.append((at, nbytes))


def scan_records(data: bytes, pos: int, record: struct.Struct, tags: Collection[bytes]) -> Scan:
    """Every intact record of a framed file's ``data`` from offset ``pos`` (the first record) on.

    A record is intact when it fits in ``data`` and its CRC-32 matches (records of tags this code does not know
    are returned too: a newer writer's, for the caller to ignore). After a damaged one the scan resumes at the
    next offset where an intact record of one of ``tags`` starts.
    """
    scan = Scan()
    while pos < len(data):
        end = _intact_end(data, pos, record)
        if end is None:
            nxt = _next_intact(data, pos + 1, record, tags)
            if nxt is None:
                break
            scan.skip(nxt - pos, at=pos)
            pos = nxt
            continue
        tag, _, t_host = record.unpack_from(data, pos)
        scan.records.append((tag, t_host, data[pos + record.size:end - CRC32.size]))
        pos = end
    scan.truncated_bytes = len(data) - pos
    return scan


def _intact_end(data: bytes, pos: int, record: struct.Struct, tags: Collection[bytes] | None = None) -> int | None:
    """The offset after the record at ``pos`` when it is intact (and, given ``tags``, of one of them), else None."""
    if pos + record.size + CRC32.size > len(data) or (tags is not None and data[pos:pos + 2] not in tags):
        return None
    _, length, _ = record.unpack_from(data, pos)
    stop = pos + record.size + length
    if stop + CRC32.size > len(data) or zlib.crc32(data[pos:stop]) != CRC32.unpack_from(data, stop)[0]:
        return None
    return stop + CRC32.size


def _next_intact(data: bytes, start: int, record: struct.Struct, tags: Collection[bytes]) -> int | None:
    """The first offset >= ``start`` where an intact record begins (candidates: where a tag occurs)."""
    while True:
        hits = [i for i in (data.find(tag, start) for tag in tags) if i >= 0]
        if not hits:
            return None
        candidate = min(hits)
        if _intact_end(data, candidate, record, tags) is not None:
            return candidate
        start = candidate + 1
