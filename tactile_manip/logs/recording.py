"""Sensor recordings on disk: the file format, an append-only writer that survives a crash, and the reader.

Layout (version 1)::

    line 1   b"tactile_manip recording\\n"
    line 2   one JSON object + b"\\n": format version, source, chip LSBs, protocol version, code version, ...
    records  tag (2 bytes) | payload length u16 | t_host_s f64 | payload | crc32 u32, little-endian;
             the CRC-32 (zlib) covers tag, length, time and payload.

Tags: ``FR`` a wire frame exactly as received, in the header's ``wire_format`` (``supermag``, the default:
sync to CRC-16 with seq, device time, status, raw counts, temperatures; ``anyskin``: one float32 line of
the header's ``layout`` chips, whose sequence is the record order), ``HL`` a JSON health snapshot, ``EV`` a
JSON event. ``t_host_s`` is the recording host's ``time.monotonic()`` when the frame became available. The
writer flushes and ``fsync``s every ``sync_every_s`` (0.5 s by default), so a killed recorder leaves every
frame up to that long before the kill; the reader skips a damaged record in the middle (resyncing on the next
intact one) and stops at an incomplete tail (a crash), and reports both.

This module reads and writes the bytes only (numpy and the core, :mod:`tactile_manip.wire` for the frames), so
the data layer reads recordings without the sensors layer; recording a live sensor
(:class:`~tactile_manip.sensors.recording.Recorder`) is :mod:`tactile_manip.sensors.recording`.
"""

from __future__ import annotations

import dataclasses
import json
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.boards import DEFAULT_BOARD, load_board
from tactile_manip.chips import ChipModelSpec
from tactile_manip.errors import ProtocolError, RecordingError
from tactile_manip.logs.framed_file import (CRC32, TAG_EVENT, FramedWriter, Scan, json_default, read_header,
                                            scan_records)
from tactile_manip.wire import make_decoder
from tactile_manip.wire.protocol import TEMPERATURE_LSB_C, VERSION, CountScale, Unwrapper, decode_frame

MAGIC = b"tactile_manip recording\n"
FORMAT_VERSION = 1
RECORD = struct.Struct("<2sHd")
TAG_FRAME, TAG_HEALTH = b"FR", b"HL"


class RecordingWriter(FramedWriter):
    """Append records to a new recording file (see the module docstring for the layout).

    Args:
        path: file to create (an existing file is replaced).
        header: JSON-serialisable metadata; ``chip`` must hold ``lsb_xy_ut``, ``lsb_z_ut``, ``saturation_counts``.
        sync_every_s: flush and fsync at least this often when records keep coming, s.
    """

    def __init__(self, path: str | Path, header: dict[str, Any], *, sync_every_s: float = 0.5) -> None:
        head = {"format": "tactile_manip.recording", "format_version": FORMAT_VERSION, "protocol_version": VERSION,
                **header}
        super().__init__(path, MAGIC, head, RECORD, sync_every_s=sync_every_s, sync_on_write=False)
        self.frames = 0

    def write_frame(self, t_host_s: float, wire: bytes) -> None:
        self.write_record(TAG_FRAME, t_host_s, wire)
        self.frames += 1

    def write_health(self, t_host_s: float, health: dict[str, Any]) -> None:
        self.write_record(TAG_HEALTH, t_host_s, json.dumps(health, default=json_default).encode())


@dataclass(frozen=True, eq=False)
class Recording:
    """A recording read back. Arrays have one entry per frame, in file order.

    Attributes:
        path: the file.
        header: the JSON header (source, chip, versions, ...).
        t_host_s: (N,) host monotonic time of each frame, s.
        seq: (N,) int64 frame counter, unwrapped.
        t_device_s: (N,) device clock, unwrapped, s.
        status: (N,) uint16 device status bits.
        counts: (N, 4, 4, 3) int16 raw counts, or None for wire formats that send microtesla (see ``raw_ut``).
        temperature_c: (N, 4, 4) float32 chip temperatures (NaN where a frame had none), or None.
        health: health snapshots, each a dict with its ``t_host_s``.
        events: events, each a dict with its ``t_host_s``.
        truncated_bytes: bytes after the last complete record (a crash's torn tail), 0 for a clean file.
        raw_ut: (N, R, C, 3) float32 raw fields of formats that send microtesla (``counts`` is None then).
        saturated_mask: (N, R, C, 3) bool saturation of those formats, else None (derived from counts).
        skipped_bytes: bytes of damaged records in the middle that were skipped (0 for an undamaged file).
        damaged_records: places where damage was skipped (each one or more lost records).
        damage: ``(byte offset, bytes)`` of each damaged place (offset -1: an intact record that is no frame).
        frame_record_bytes: bytes of one frame record on disk (the median of the intact ones; 0 without frames).
    """

    path: Path
    header: dict[str, Any]
    t_host_s: np.ndarray
    seq: np.ndarray
    t_device_s: np.ndarray
    status: np.ndarray
    counts: np.ndarray
    temperature_c: np.ndarray | None
    health: list[dict[str, Any]] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    truncated_bytes: int = 0
    raw_ut: np.ndarray | None = None
    saturated_mask: np.ndarray | None = None
    skipped_bytes: int = 0
    damaged_records: int = 0
    damage: tuple[tuple[int, int], ...] = ()
    frame_record_bytes: int = 0

    def __len__(self) -> int:
        return len(self.seq)

    @property
    def frames_lost(self) -> int:
        """About how many frames the damaged places and the torn tail held: their bytes over one frame record's
        (0 for an undamaged file; health and event records in the damage count as frames)."""
        lost = self.skipped_bytes + self.truncated_bytes
        return 0 if not lost or not self.frame_record_bytes else max(1, round(lost / self.frame_record_bytes))

    @property
    def scale(self) -> CountScale:
        chip = self.header["chip"]
        return CountScale(chip["lsb_xy_ut"], chip["lsb_z_ut"], chip.get("saturation_counts", 32767))

    @property
    def layout_name(self) -> str:
        """The board layout the frames were recorded with (recordings before layouts existed: supermag-4x4)."""
        return self.header.get("layout", DEFAULT_BOARD)

    def field_raw_ut(self) -> np.ndarray:
        """(N, R, C, 3) float32 raw fields in uT (counts times the recorded LSBs, or as the wire sent them)."""
        return self.raw_ut if self.counts is None else self.scale.to_ut(self.counts)

    def saturated(self) -> np.ndarray:
        """(N, R, C, 3) bool, channels at the rail."""
        if self.counts is None:
            return self.saturated_mask
        return self.scale.saturated(self.counts)


def read_recording(path: str | Path) -> Recording:
    """Read a recording, skipping damaged records and a torn last one (``Recording.skipped_bytes``,
    ``damaged_records``, ``truncated_bytes`` say how much).

    Raises:
        RecordingError: missing file, not a recording, or a newer format version.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError as e:
        raise RecordingError(f"recording not found: {path}") from e
    header, pos = _read_header(data, path)
    decode = _record_decoder(header, path)
    scan = scan_records(data, pos, RECORD, (TAG_FRAME, TAG_HEALTH, TAG_EVENT))
    frames, health, events, sizes = [], [], [], []
    for tag, t_host, payload in scan.records:
        try:
            if tag == TAG_FRAME:
                frames.append((t_host, decode(payload)))
                sizes.append(RECORD.size + len(payload) + CRC32.size)
            elif tag in (TAG_HEALTH, TAG_EVENT):  # other tags: a newer writer's records, skipped
                (health if tag == TAG_HEALTH else events).append({"t_host_s": t_host, **json.loads(payload)})
        except (ProtocolError, ValueError, TypeError):  # intact on disk but not a frame / JSON object: skip it
            scan.skip(RECORD.size + len(payload) + CRC32.size)
    rec = _assemble(path, header, frames, health, events, scan)
    return dataclasses.replace(rec, damage=tuple(scan.places), frame_record_bytes=int(np.median(sizes)) if sizes else 0)


def _read_header(data: bytes, path: Path) -> tuple[dict[str, Any], int]:
    return read_header(data, path, MAGIC, "recording", FORMAT_VERSION)


def _record_decoder(header: dict[str, Any], path: Path) -> Callable[[bytes], Any]:
    """How this file's FR payloads decode: the SuperMag codec, or the header's wire format on its layout."""
    fmt = header.get("wire_format", "supermag")
    if fmt == "supermag":
        return decode_frame
    try:
        layout = load_board(header.get("layout", ""))
        chip = header.get("chip", {})
        params = ChipModelSpec(**{k: chip[k] for k in ("lsb_xy_ut", "lsb_z_ut", "saturation_counts") if k in chip})
        return make_decoder(fmt, n_chips=layout.n_chips, chip=params).decode_record
    except ValueError as e:
        raise RecordingError(f"{path}: cannot read its frames: {e}") from None


def _assemble(path: Path, header: dict[str, Any], frames: list, health: list, events: list, scan: Scan) -> Recording:
    if header.get("wire_format", "supermag") != "supermag":
        return _assemble_fields(path, header, frames, health, events, scan)
    n = len(frames)
    seq, clock = Unwrapper(16), Unwrapper(32)
    counts = np.empty((n, 4, 4, 3), np.int16)
    temps = np.full((n, 4, 4), np.nan, np.float32) if any(f.temperature_raw is not None for _, f in frames) else None
    seqs, t_dev = np.empty(n, np.int64), np.empty(n)
    for i, (_, f) in enumerate(frames):
        seqs[i] = seq.update(f.seq)[0]
        t_dev[i] = clock.update(f.t_mcu_us)[0] * 1e-6
        counts[i] = f.counts
        if temps is not None and f.temperature_raw is not None:
            temps[i] = f.temperature_raw * TEMPERATURE_LSB_C
    return Recording(path=path, header=header, t_host_s=np.array([t for t, _ in frames], np.float64), seq=seqs,
                     t_device_s=t_dev, status=np.array([f.status for _, f in frames], np.uint16), counts=counts,
                     temperature_c=temps, health=health, events=events, truncated_bytes=scan.truncated_bytes,
                     skipped_bytes=scan.skipped_bytes, damaged_records=scan.damaged_records)


def _assemble_fields(path: Path, header: dict[str, Any], frames: list, health: list, events: list,
                     scan: Scan) -> Recording:
    """A recording of a format that sends microtesla and no counter: sequence = record order, no device time."""
    layout = load_board(header["layout"])
    n = len(frames)
    raw = np.zeros((n, *layout.shape), np.float32)
    sat = np.zeros((n, *layout.shape), bool)
    temps = None if not any(f.temperature_c is not None for _, f in frames) else np.full((n, *layout.grid), np.nan,
                                                                                          np.float32)
    for i, (_, f) in enumerate(frames):
        raw[i] = layout.reading_from_chips(f.field_ut)
        sat[i] = layout.saturation_from_chips(f.saturated)
        if temps is not None and f.temperature_c is not None:
            temps[i] = layout.cells_from_chips(f.temperature_c)
    return Recording(path=path, header=header, t_host_s=np.array([t for t, _ in frames], np.float64),
                     seq=np.arange(n, dtype=np.int64), t_device_s=np.full(n, np.nan),
                     status=np.array([f.status for _, f in frames], np.uint16), counts=None, temperature_c=temps,
                     health=health, events=events, truncated_bytes=scan.truncated_bytes,
                     skipped_bytes=scan.skipped_bytes, damaged_records=scan.damaged_records, raw_ut=raw,
                     saturated_mask=sat)
