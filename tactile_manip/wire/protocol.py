"""The MBTS wire protocol (docs/design.md, Wire protocol) as a pure codec: frame layout, CRC, encoder, stream decoder.

A frame, little-endian::

    offset  size  field
         0     2  sync 0xAA 0x55
         2     1  version (1)
         3     1  flags: bit 0 set when the temperatures T are present
         4     2  seq, u16, +1 per frame, wraps at 2**16
         6     4  t_mcu_us, u32, device clock in microseconds, wraps at 2**32 (~71.6 min)
        10     2  status, u16, device status bits (0 = all chips read fine)
        12    96  B[16][3], int16 raw counts; chips row-major over (row, col) of the 4x4 grid, axes x, y, z
       108    32  T[16], int16 chip temperatures in 0.01 degC (only when flags bit 0)
    -2 (108/140) 2  crc16, CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over every byte after the sync

so a frame is 110 bytes (142 with temperatures). No I/O here: :class:`FrameDecoder` takes whatever bytes a
port delivered and returns the complete frames whose CRC matches, skipping everything else one byte at a
time, so it resynchronises on the next good frame after any corruption.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from tactile_manip.chips import ChipSettings
from tactile_manip.errors import ProtocolError

SYNC = b"\xaa\x55"
VERSION = 1
FLAG_TEMPERATURE = 0x01
GRID = (4, 4)
N_CHIPS = GRID[0] * GRID[1]
TEMPERATURE_LSB_C = 0.01
HEADER = struct.Struct("<2sBBHIH")            # sync, version, flags, seq, t_mcu_us, status
CRC = struct.Struct("<H")
HEADER_LEN = HEADER.size                       # 12
FIELD_LEN = N_CHIPS * 3 * 2                    # 96
TEMPERATURE_LEN = N_CHIPS * 2                  # 32
FRAME_LEN = HEADER_LEN + FIELD_LEN + CRC.size  # 110
FRAME_LEN_T = FRAME_LEN + TEMPERATURE_LEN      # 142
_INT16 = np.dtype("<i2")


def crc16(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (the check value of ``b"123456789"`` is 0x29B1)."""
    return binascii.crc_hqx(data, 0xFFFF)


class Frame(NamedTuple):
    """One decoded wire frame (values as on the wire: ``seq`` and ``t_mcu_us`` are not unwrapped).

    Attributes:
        seq: u16 frame counter.
        t_mcu_us: u32 device clock, microseconds.
        status: u16 device status bits.
        flags: the flags byte.
        counts: (4, 4, 3) int16 raw counts, read-only, ``[row, col, axis]``.
        temperature_raw: (4, 4) int16 in 0.01 degC, or None when the frame carries none.
        raw: the complete frame, sync to CRC (what a recorder stores).
        version: protocol version byte.
    """

    seq: int
    t_mcu_us: int
    status: int
    flags: int
    counts: np.ndarray
    temperature_raw: np.ndarray | None
    raw: bytes
    version: int = VERSION


def frame_length(flags: int) -> int:
    """Length in bytes of a frame with this flags byte."""
    return FRAME_LEN_T if flags & FLAG_TEMPERATURE else FRAME_LEN


def encode_frame(counts: np.ndarray, *, seq: int, t_mcu_us: int, status: int = 0,
                 temperature_raw: np.ndarray | None = None) -> bytes:
    """Build one wire frame.

    Args:
        counts: (4, 4, 3) integer raw counts within int16 (``[row, col, axis]``).
        seq: frame counter; wrapped to u16 (the wire field width).
        t_mcu_us: device clock in us; wrapped to u32.
        status: u16 device status bits.
        temperature_raw: optional (4, 4) int16 temperatures in 0.01 degC; sets flags bit 0.

    Raises:
        ProtocolError: wrong shape, or a value outside its field.
    """
    c = np.asarray(counts)
    if c.shape != GRID + (3,):
        raise ProtocolError(f"counts: expected shape (4, 4, 3), got {c.shape}")
    if not np.issubdtype(c.dtype, np.integer) or c.min() < -32768 or c.max() > 32767:
        raise ProtocolError("counts must be integers within int16 [-32768, 32767]")
    if not 0 <= status <= 0xFFFF:
        raise ProtocolError(f"status must be a u16, got {status}")
    flags, tail = 0, b""
    if temperature_raw is not None:
        t = np.asarray(temperature_raw)
        if t.shape != GRID or not np.issubdtype(t.dtype, np.integer):
            raise ProtocolError(f"temperature_raw: expected (4, 4) integers, got {t.shape} {t.dtype}")
        flags, tail = FLAG_TEMPERATURE, t.astype(_INT16).tobytes()
    body = (HEADER.pack(SYNC, VERSION, flags, seq & 0xFFFF, t_mcu_us & 0xFFFFFFFF, status)[2:]
            + c.astype(_INT16).tobytes() + tail)
    return SYNC + body + CRC.pack(crc16(body))


def _parse(raw: bytes) -> Frame:
    """Unpack a frame whose length and CRC were already checked."""
    _, version, flags, seq, t_mcu_us, status = HEADER.unpack_from(raw)
    counts = np.frombuffer(raw, _INT16, N_CHIPS * 3, HEADER_LEN).reshape(4, 4, 3)
    temps = None
    if flags & FLAG_TEMPERATURE:
        temps = np.frombuffer(raw, _INT16, N_CHIPS, HEADER_LEN + FIELD_LEN).reshape(GRID)
    return Frame(seq, t_mcu_us, status, flags, counts, temps, raw, version)


def decode_frame(data: bytes) -> Frame:
    """Decode exactly one complete frame (for stored frames); raise ProtocolError naming what is wrong."""
    raw = bytes(data)
    if len(raw) < HEADER_LEN or raw[:2] != SYNC:
        raise ProtocolError(f"not a frame: expected sync AA 55 and >= {HEADER_LEN} bytes, got {raw[:2].hex()} "
                            f"and {len(raw)} bytes")
    if raw[2] != VERSION:
        raise ProtocolError(f"frame has protocol version {raw[2]}; this driver reads version {VERSION}")
    n = frame_length(raw[3])
    if len(raw) != n:
        raise ProtocolError(f"frame with flags {raw[3]:#04x} must be {n} bytes, got {len(raw)}")
    if crc16(raw[2:-2]) != CRC.unpack_from(raw, n - 2)[0]:
        raise ProtocolError("frame CRC does not match")
    return _parse(raw)


@dataclass
class DecoderStats:
    """Counters of a :class:`FrameDecoder` since it was created (``reset()`` keeps them).

    Attributes:
        frames: frames accepted.
        crc_errors: candidate frames (sync, known version, complete) whose CRC did not match.
        version_errors: syncs followed by a version byte this decoder does not read.
        frame_errors: candidate frames refused by a length or value check (wire formats without a CRC).
        resync_bytes: bytes skipped while looking for a good frame (including dropped buffer tails).
        bytes_in: bytes fed in total.
    """

    frames: int = 0
    crc_errors: int = 0
    version_errors: int = 0
    frame_errors: int = 0
    resync_bytes: int = 0
    bytes_in: int = 0


class FrameDecoder:
    """Stream decoder: feed it bytes as they come, get the complete frames whose CRC matches.

    The result does not depend on how the stream is chunked. Every byte fed ends up in exactly one of: an
    accepted frame, ``stats.resync_bytes``, or the (at most one frame long) pending buffer.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.stats = DecoderStats()

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def reset(self) -> None:
        """Forget buffered bytes (after a port was reopened); they count as resync bytes."""
        self.stats.resync_bytes += len(self._buf)
        self._buf.clear()

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame]:
        """Append ``data`` and return every complete, CRC-valid frame now available, oldest first."""
        buf = self._buf
        buf += data
        st = self.stats
        st.bytes_in += len(data)
        frames: list[Frame] = []
        pos, n = 0, len(buf)
        while True:
            i = buf.find(SYNC, pos)
            if i < 0:
                keep = 1 if n > pos and buf[n - 1] == 0xAA else 0  # a sync may straddle two reads
                st.resync_bytes += n - keep - pos
                pos = n - keep
                break
            st.resync_bytes += i - pos
            pos = i
            if n - i < 4:
                break
            if buf[i + 2] != VERSION:
                st.version_errors += 1
                st.resync_bytes += 1
                pos = i + 1
                continue
            length = FRAME_LEN_T if buf[i + 3] & FLAG_TEMPERATURE else FRAME_LEN
            if n - i < length:
                break
            raw = bytes(buf[i:i + length])
            if binascii.crc_hqx(raw[2:-2], 0xFFFF) != raw[-2] | raw[-1] << 8:
                st.crc_errors += 1
                st.resync_bytes += 1
                pos = i + 1
                continue
            frames.append(_parse(raw))
            pos = i + length
        del buf[:pos]
        st.frames += len(frames)
        return frames


class Unwrapper:
    """Unwrap a counter of ``bits`` bits that moves forward by less than half its range between updates."""

    def __init__(self, bits: int) -> None:
        self._mod = 1 << bits
        self._half = 1 << (bits - 1)
        self._last_raw: int | None = None
        self.value = -1  # last unwrapped value, -1 before the first

    def update(self, raw: int) -> tuple[int, int]:
        """Return ``(unwrapped, step)``, ``step`` being the raw change since the previous value (1 for the first).

        A step of 0 or backwards (a repeat or a device restart) is reported as it is (<= 0) and the unwrapped
        value continues at ``previous + 1`` so it stays strictly increasing.
        """
        if self._last_raw is None:
            self._last_raw, self.value = raw, raw
            return raw, 1
        step = (raw - self._last_raw) % self._mod
        if step >= self._half:
            step -= self._mod
        self._last_raw = raw
        self.value += step if step > 0 else 1
        return self.value, step


class CountScale:
    """Raw counts to microtesla for one chip setting (LSBs and rail)."""

    def __init__(self, lsb_xy_ut: float, lsb_z_ut: float, saturation_counts: int = 32767) -> None:
        self.lsb_ut = np.array([lsb_xy_ut, lsb_xy_ut, lsb_z_ut], dtype=np.float32)
        self.saturation_counts = int(saturation_counts)

    @classmethod
    def from_chip(cls, chip: ChipSettings) -> CountScale:
        """From a chip's settings (:class:`~tactile_manip.chips.ChipSettings`: LSBs and rail)."""
        return cls(chip.lsb_xy_ut, chip.lsb_z_ut, chip.saturation_counts)

    def to_ut(self, counts: np.ndarray) -> np.ndarray:
        """(..., 3) int counts to float32 uT (x, y at the xy LSB, z at the z LSB)."""
        return counts * self.lsb_ut

    def to_counts(self, field_ut: np.ndarray) -> np.ndarray:
        """(..., 3) uT to the nearest int16 counts, clipped to the rail (inverse of :meth:`to_ut`)."""
        rail = self.saturation_counts
        return np.clip(np.rint(np.asarray(field_ut, np.float64) / self.lsb_ut), -rail, rail).astype(np.int16)

    def saturated(self, counts: np.ndarray) -> np.ndarray:
        """Boolean mask of counts at the rail."""
        return np.abs(counts.astype(np.int32)) >= self.saturation_counts
