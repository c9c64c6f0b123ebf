"""The collector's crash-safe pair log, its reader, and its conversion to the paired dataset format.

Layout (version 1)::

    line 1   b"tactile_manip pairs\\n"
    line 2   one JSON object + b"\\n": format version, collection config, calibration summary, code version, ...
    records  tag (2 bytes) | payload length u32 | t_host_s f64 | payload | crc32 u32, little-endian;
             the CRC-32 (zlib) covers tag, length, time and payload.

Tags: ``PR`` a pair: u16 JSON length | JSON (times, sequence numbers, force, object, pose, shapes) | field_ut
float32 | field_raw_ut float32 | saturated uint8 | zlib-compressed depth_q uint8 (0.01 mm units); ``EV`` a
JSON event (reference, baseline, trigger, unpaired frame, stop). The writer appends only and fsyncs at least
every ``sync_every_s``; the reader stops at the first incomplete or damaged record (a crash's torn tail).
:func:`dataset_from_pair_logs` turns one or more logs into a :class:`~tactile_manip.data.PairedDataset`
that ``tactile-manip train`` and ``evaluate`` read unchanged.
"""

from __future__ import annotations

import json
import math
import struct
import time
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.errors import RecordingError
from tactile_manip.logs.framed_file import (CRC32, TAG_EVENT, FramedWriter, json_default, read_header,
                                            scan_records)
from tactile_manip.data import DEPTH_SCALE_MM, SPLITS, PairedDataset, depth_image_spec
from tactile_manip.version import code_version

MAGIC = b"tactile_manip pairs\n"
FORMAT_VERSION = 1
RECORD = struct.Struct("<2sId")
JSON_LEN = struct.Struct("<H")
TAG_PAIR = b"PR"


@dataclass(frozen=True, eq=False)
class PairRecord:
    """One synchronized pair as logged (arrays in the dataset's layout and units)."""

    field_ut: np.ndarray        # (R, C, 3) float32, baseline-subtracted, uT
    field_raw_ut: np.ndarray    # (R, C, 3) float32, uT
    saturated: np.ndarray       # (R, C, 3) bool
    depth_q: np.ndarray         # (H, W) uint8, units of DEPTH_SCALE_MM
    info: dict[str, Any]        # t_depth_s, t_field_s, dt_s, seq_depth, seq_field, force_n, object, pose, press


class PairLogWriter(FramedWriter):
    """Append pairs and events to a new pair log (an existing file is replaced)."""

    def __init__(self, path: str | Path, header: dict[str, Any], *, sync_every_s: float = 0.5) -> None:
        head = {"format": "tactile_manip.pairs", "format_version": FORMAT_VERSION, **header}
        super().__init__(path, MAGIC, head, RECORD, sync_every_s=sync_every_s)
        self.pairs = 0

    def write_pair(self, t_host_s: float, record: PairRecord) -> None:
        meta = json.dumps({**record.info, "field_shape": list(record.field_ut.shape),
                           "depth_shape": list(record.depth_q.shape)}, default=json_default).encode()
        payload = b"".join([JSON_LEN.pack(len(meta)), meta, np.ascontiguousarray(record.field_ut, "<f4").tobytes(),
                            np.ascontiguousarray(record.field_raw_ut, "<f4").tobytes(),
                            np.ascontiguousarray(record.saturated, np.uint8).tobytes(),
                            zlib.compress(np.ascontiguousarray(record.depth_q, np.uint8).tobytes(), 1)])
        self.write_record(TAG_PAIR, t_host_s, payload)
        self.pairs += 1

@dataclass(frozen=True, eq=False)
class PairLog:
    """A pair log read back: header, pairs in file order, events, the size of a torn tail (0 when clean) and what
    was skipped as damaged in the middle (bytes and places; see ``framed_file.Scan``)."""

    path: Path
    header: dict[str, Any]
    pairs: list[PairRecord]
    events: list[dict[str, Any]] = field(default_factory=list)
    truncated_bytes: int = 0
    skipped_bytes: int = 0
    damaged_records: int = 0

    def __len__(self) -> int:
        return len(self.pairs)


def read_pair_log(path: str | Path) -> PairLog:
    """Read a pair log, tolerating a torn last record.

    Raises:
        RecordingError: missing file, not a pair log, or a newer format.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError as e:
        raise RecordingError(f"pair log not found: {path}") from e
    header, pos = read_header(data, path, MAGIC, "pair log", FORMAT_VERSION)
    scan = scan_records(data, pos, RECORD, (TAG_PAIR, TAG_EVENT))
    pairs, events = [], []
    for tag, _, payload in scan.records:
        try:
            if tag == TAG_PAIR:
                pairs.append(_decode_pair(payload))
            elif tag == TAG_EVENT:  # other tags: a newer writer's records, skipped
                events.append(json.loads(payload))
        except (ValueError, zlib.error, struct.error):  # intact on disk but not a pair / JSON: skip it
            scan.skip(RECORD.size + len(payload) + CRC32.size)
    return PairLog(path, header, pairs, events, truncated_bytes=scan.truncated_bytes,
                   skipped_bytes=scan.skipped_bytes, damaged_records=scan.damaged_records)


def _decode_pair(payload: bytes) -> PairRecord:
    (n,) = JSON_LEN.unpack_from(payload, 0)
    info = json.loads(payload[2:2 + n])
    fshape, dshape = tuple(info.pop("field_shape")), tuple(info.pop("depth_shape"))
    k = int(np.prod(fshape))
    pos = 2 + n
    field_ut = np.frombuffer(payload, "<f4", k, pos).reshape(fshape).astype(np.float32)
    raw = np.frombuffer(payload, "<f4", k, pos + 4 * k).reshape(fshape).astype(np.float32)
    sat = np.frombuffer(payload, np.uint8, k, pos + 8 * k).reshape(fshape).astype(bool)
    depth = np.frombuffer(zlib.decompress(payload[pos + 9 * k:]), np.uint8).reshape(dshape)
    return PairRecord(field_ut, raw, sat, depth, info)


def dataset_from_pair_logs(logs: Sequence[PairLog | str | Path], *, test_objects: Sequence[str] = (),
                           validation_fraction: float = 0.1) -> PairedDataset:
    """One paired dataset from pair logs, in log and time order.

    Splits follow the simulator's rule: samples of ``test_objects`` are 'test'; of every other object the
    last ``validation_fraction`` (in collection order) are 'val', the rest 'train'. Unknown poses are NaN.

    Raises:
        ValueError: no pairs, inconsistent shapes across logs, or a bad fraction.
    """
    if not 0 <= validation_fraction < 1:
        raise ValueError(f"validation_fraction must be in [0, 1), got {validation_fraction}")
    logs = [log if isinstance(log, PairLog) else read_pair_log(log) for log in logs]
    pairs = [p for log in logs for p in log.pairs]
    if not pairs:
        raise ValueError("the pair logs hold no pairs: nothing to write (did a press reach the force threshold?)")
    shapes = {(p.field_ut.shape, p.depth_q.shape) for p in pairs}
    if len(shapes) > 1:
        raise ValueError(f"the pair logs mix sensor shapes {sorted(shapes)}: collect each sensor into its own dataset")
    names = [str(p.info.get("object", "object")) for p in pairs]
    unique = list(dict.fromkeys(names))
    split = _splits(names, set(test_objects), validation_fraction)
    pose = np.array([p.info.get("pose") or [math.nan] * 5 for p in pairs], np.float32)
    force = np.array([p.info.get("force_n", math.nan) for p in pairs], np.float32)
    depth_q = np.stack([p.depth_q for p in pairs])
    dts = np.array([abs(p.info["dt_s"]) for p in pairs])
    first = logs[0].header
    provenance = {
        "source": "tactile-manip collect", "logs": [str(log.path) for log in logs],
        "collection": [log.header for log in logs], "test_objects": list(test_objects),
        "sync": {"pairs": len(pairs), "max_abs_dt_s": float(dts.max()), "mean_abs_dt_s": float(dts.mean()),
                 "tolerance_s": max(float(log.header.get("config", {}).get("tolerance_s", math.nan)) for log in logs)},
        "code_version": code_version(), "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    extras = {
        "field_raw_ut": np.stack([p.field_raw_ut for p in pairs]), "saturated": np.stack([p.saturated for p in pairs]),
        "pose": pose, "force_n": force,
        "approach_mm": depth_q.reshape(len(pairs), -1).max(axis=1).astype(np.float32) * np.float32(DEPTH_SCALE_MM),
        "skin_approach_mm": np.full(len(pairs), np.nan, np.float32),
        "contact": np.array([bool(p.info.get("contact", True)) for p in pairs])}
    return PairedDataset(
        readings=np.stack([p.field_ut for p in pairs]), images=depth_q, split=split,
        image=depth_image_spec(float(first.get("pixel_mm", 0.1))),
        object_index=np.array([unique.index(n) for n in names], np.int16), object_names=np.array(unique),
        extras=extras, provenance=provenance)


def _splits(names: list[str], test: set[str], validation_fraction: float) -> np.ndarray:
    out = np.empty(len(names), dtype="U5")
    for name in dict.fromkeys(names):
        idx = [i for i, n in enumerate(names) if n == name]
        if name in test:
            out[idx] = "test"
            continue
        n_train = int(math.floor(len(idx) * (1.0 - validation_fraction)))
        out[idx[:n_train]] = "train"
        out[idx[n_train:]] = "val"
    assert set(out.tolist()) <= set(SPLITS)
    return out
