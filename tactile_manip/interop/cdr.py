"""Plain CDR (XCDR1, little endian), the ROS 2 wire format, for the few message types the MCAP export writes.

A message is its 4-byte encapsulation header (``00 01 00 00``: CDR, little endian, no options) and then the
fields in order. Each primitive sits at an offset, counted from the end of the header, that is a multiple of
its size (8 at most); padding bytes are zero. A string is a uint32 byte count that includes the terminating
NUL, the UTF-8 bytes and the NUL. A sequence (``T[]``) is a uint32 element count and the elements; an empty
sequence adds no padding (elements are aligned one by one, so only a first element would be). A fixed-size
array (``T[N]``, e.g. a covariance's ``float64[9]``) is its N elements with no count. Nested
messages are their fields inline, without a header or padding of their own.

Messages are plain dicts (``{"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "pad"}, ...}``),
numeric sequences numpy arrays, ``uint8[]`` bytes. The types come from
:data:`tactile_manip.interop.ros_msgs.MESSAGES`. This module imports numpy only.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from typing import Any

import numpy as np

HEADER = b"\x00\x01\x00\x00"       # CDR_LE encapsulation, options 0
# primitive -> (struct format, size in bytes, numpy dtype)
PRIMITIVES: dict[str, tuple[str, int, str]] = {
    "bool": ("?", 1, "?"), "byte": ("B", 1, "u1"), "char": ("B", 1, "u1"),
    "int8": ("b", 1, "i1"), "uint8": ("B", 1, "u1"), "int16": ("h", 2, "<i2"), "uint16": ("H", 2, "<u2"),
    "int32": ("i", 4, "<i4"), "uint32": ("I", 4, "<u4"), "int64": ("q", 8, "<i8"), "uint64": ("Q", 8, "<u8"),
    "float32": ("f", 4, "<f4"), "float64": ("d", 8, "<f8"),
}


def split_type(field_type: str) -> tuple[str, bool]:
    """``"float32[]"`` -> ("float32", True), ``"float64[9]"`` -> ("float64", True) (an array either way: see
    :func:`array_size`); bounded types (``T[<=N]``, ``string<=N``) are refused."""
    if field_type.endswith("[]"):
        return field_type[:-2], True
    if array_size(field_type) is not None:
        return field_type[:field_type.index("[")], True
    if "[" in field_type or "<" in field_type:
        raise ValueError(f"CDR: unsupported field type {field_type!r} (only T, T[] and T[N] here)")
    return field_type, False


def array_size(field_type: str) -> int | None:
    """N of a fixed-size array type ``T[N]``; None for any other type."""
    if not field_type.endswith("]") or "[" not in field_type:
        return None
    size = field_type[field_type.index("[") + 1:-1]
    return int(size) if size.isdigit() else None


class CdrWriter:
    """Appends fields to one message, aligning each primitive relative to the end of the header."""

    def __init__(self) -> None:
        self.buf = bytearray(HEADER)

    def align(self, size: int) -> None:
        self.buf += b"\0" * (-(len(self.buf) - len(HEADER)) % size)

    def primitive(self, kind: str, value: Any) -> None:
        fmt, size, _ = PRIMITIVES[kind]
        self.align(size)
        self.buf += struct.pack("<" + fmt, value)

    def string(self, value: str) -> None:
        data = value.encode("utf-8")
        if b"\0" in data:
            raise ValueError(f"CDR: a string may not hold NUL, got {value!r}")
        self.primitive("uint32", len(data) + 1)
        self.buf += data + b"\0"

    def sequence(self, kind: str, values: Any) -> None:
        if kind in ("uint8", "byte", "char") and isinstance(values, (bytes, bytearray, memoryview)):
            self.primitive("uint32", len(values))
            self.buf += values
            return
        arr = np.asarray(values, dtype=PRIMITIVES[kind][2])
        if arr.ndim != 1:
            raise ValueError(f"CDR: a {kind}[] takes a flat sequence, got shape {arr.shape}")
        self.primitive("uint32", len(arr))
        if len(arr):
            self.align(PRIMITIVES[kind][1])
            self.buf += arr.tobytes()

    def bytes(self) -> bytes:
        return bytes(self.buf)


class CdrReader:
    """Reads fields back in the order :class:`CdrWriter` wrote them."""

    def __init__(self, data: bytes) -> None:
        if len(data) < 4 or data[:2] != HEADER[:2]:
            raise ValueError(f"CDR: expected the little-endian CDR header 00 01, got {data[:4].hex(' ')}")
        self.data, self.pos = memoryview(data), len(HEADER)

    def align(self, size: int) -> None:
        self.pos += -(self.pos - len(HEADER)) % size

    def _take(self, n: int) -> memoryview:
        if self.pos + n > len(self.data):
            raise ValueError(f"CDR: message ends at byte {len(self.data)}, needed {self.pos + n}")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def primitive(self, kind: str) -> Any:
        fmt, size, _ = PRIMITIVES[kind]
        self.align(size)
        return struct.unpack("<" + fmt, self._take(size))[0]

    def string(self) -> str:
        n = self.primitive("uint32")
        raw = bytes(self._take(n))
        if n == 0 or raw[-1] != 0:
            raise ValueError("CDR: a string must end with NUL (its length counts it)")
        return raw[:-1].decode("utf-8")

    def sequence(self, kind: str) -> Any:
        n = self.primitive("uint32")
        if kind in ("uint8", "byte", "char"):
            return bytes(self._take(n))
        _, size, dtype = PRIMITIVES[kind]
        if n:
            self.align(size)
        return np.frombuffer(self._take(n * size), dtype=dtype).copy()


def encode(messages: Mapping[str, list[tuple[str, str]]], type_name: str, msg: Mapping[str, Any]) -> bytes:
    """One CDR message of ``type_name`` (a key of ``messages``: its (field type, field name) list)."""
    w = CdrWriter()
    _write(w, messages, type_name, msg)
    return w.bytes()


def decode(messages: Mapping[str, list[tuple[str, str]]], type_name: str, data: bytes) -> dict[str, Any]:
    """The dict :func:`encode` was given (numeric sequences as numpy arrays, ``uint8[]`` as bytes)."""
    r = CdrReader(data)
    return _read(r, messages, type_name)


def _write(w: CdrWriter, messages, type_name: str, msg: Mapping[str, Any]) -> None:
    for field_type, name in messages[type_name]:
        base, is_seq = split_type(field_type)
        value = msg[name]
        size = array_size(field_type)
        if size is not None:
            _write_array(w, messages, base, size, value, name)
        elif base in PRIMITIVES and is_seq:
            w.sequence(base, value)
        elif base in PRIMITIVES:
            w.primitive(base, value)
        elif base == "string":
            if is_seq:
                w.primitive("uint32", len(value))
                for s in value:
                    w.string(s)
            else:
                w.string(value)
        elif is_seq:
            w.primitive("uint32", len(value))
            for item in value:
                _write(w, messages, base, item)
        else:
            _write(w, messages, base, value)


def _write_array(w: CdrWriter, messages, base: str, size: int, value: Any, name: str) -> None:
    """A ``T[N]`` field: its N elements and no count (a primitive array aligned once, as its elements are)."""
    if base in PRIMITIVES:
        raw = isinstance(value, (bytes, bytearray, memoryview))
        arr = np.frombuffer(bytes(value), "u1") if raw else np.asarray(value, dtype=PRIMITIVES[base][2]).reshape(-1)
        items: Any = arr
    else:
        items = list(value)
    if len(items) != size:
        raise ValueError(f"CDR: field {name!r} is a {base}[{size}], got {len(items)} values")
    if base in PRIMITIVES:
        w.align(PRIMITIVES[base][1])
        w.buf += np.ascontiguousarray(items, dtype=PRIMITIVES[base][2]).tobytes()
        return
    for item in items:
        w.string(item) if base == "string" else _write(w, messages, base, item)


def _read_array(r: CdrReader, messages, base: str, size: int) -> Any:
    if base in PRIMITIVES:
        _, width, dtype = PRIMITIVES[base]
        if base in ("uint8", "byte", "char"):
            return bytes(r._take(size))
        r.align(width)
        return np.frombuffer(r._take(size * width), dtype=dtype).copy()
    if base == "string":
        return [r.string() for _ in range(size)]
    return [_read(r, messages, base) for _ in range(size)]


def _read(r: CdrReader, messages, type_name: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for field_type, name in messages[type_name]:
        base, is_seq = split_type(field_type)
        size = array_size(field_type)
        if size is not None:
            out[name] = _read_array(r, messages, base, size)
        elif base in PRIMITIVES:
            out[name] = r.sequence(base) if is_seq else r.primitive(base)
        elif base == "string":
            out[name] = [r.string() for _ in range(r.primitive("uint32"))] if is_seq else r.string()
        elif is_seq:
            out[name] = [_read(r, messages, base) for _ in range(r.primitive("uint32"))]
        else:
            out[name] = _read(r, messages, base)
    return out
