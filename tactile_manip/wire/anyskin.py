"""The ReSkin/AnySkin binary stream behind the :class:`WireDecoder` interface.

The published AnySkin/ReSkin binary burst sketch writes, per frame, for each chip in its order four
little-endian float32 (temperature in degC, then x, y, z in uT, as the MLX90393 library converts them) and
then ``"\\r\\n"``: ``16 * n_chips + 2`` bytes, no header, no counter, no clock, no CRC, as fast as it can
read the chips (free-running). The host therefore supplies sequence and time (the serial backend counts
frames and stamps them on arrival), and this decoder finds frames by their line ending and length:

- in sync, a frame is accepted when its last two bytes are ``"\\r\\n"`` and its values are plausible (finite,
  temperature within ``TEMPERATURE_RANGE_C``, |field| <= ``MAX_FIELD_UT``); anything else loses sync;
- out of sync, a frame start is a position right after a ``"\\r\\n"`` from which *two* consecutive frames
  pass those checks (one would do, but float payloads can contain the bytes 0D 0A themselves).

Bytes skipped on the way count as ``resync_bytes``, refused in-sync frames as ``frame_errors``.
"""

from __future__ import annotations


import numpy as np

from tactile_manip.chips import MLX90393, ChipSettings, full_scale_ut
from tactile_manip.errors import ProtocolError
from tactile_manip.wire.base import ChipFrame, WireDecoder

EOL = b"\r\n"
CHIP_BYTES = 16                    # t, x, y, z as float32
TEMPERATURE_RANGE_C = (-40.0, 125.0)  # wider than the MLX90393's rated range: a sanity bound, not a spec
MAX_FIELD_UT = 1.0e5               # twice the chip's largest range (50 mT): larger values are misaligned bytes
_F32 = np.dtype("<f4")


def frame_length(n_chips: int) -> int:
    """Bytes per frame: ``16 * n_chips + 2``."""
    return CHIP_BYTES * n_chips + len(EOL)


def pack_frame(temperature_c: np.ndarray, field_ut: np.ndarray) -> bytes:
    """One frame as the sketch writes it: (n,) temperatures degC and (n, 3) fields uT, chip order."""
    t = np.asarray(temperature_c, np.float32).reshape(-1, 1)
    f = np.asarray(field_ut, np.float32).reshape(-1, 3)
    if len(t) != len(f):
        raise ValueError(f"temperature_c has {len(t)} chips, field_ut {len(f)}")
    return np.concatenate([t, f], axis=1).astype(_F32).tobytes() + EOL


class AnySkinDecoder(WireDecoder):
    """Free-running float32 frames terminated by CRLF; chip count from the board layout."""

    name = "anyskin"
    seq_bits = None
    clock_bits = None

    def __init__(self, *, n_chips: int = 5, chip: ChipSettings | None = None) -> None:
        if n_chips < 1:
            raise ValueError(f"n_chips must be >= 1, got {n_chips}")
        super().__init__(n_chips=n_chips, chip=chip or MLX90393)
        self._len = frame_length(n_chips)
        self._buf = bytearray()
        self._synced = False
        # a channel is at the rail when its value reaches the count rail times the LSB (the library's conversion)
        self._rail_ut = full_scale_ut(self.chip).astype(np.float32) * np.float32(1 - 1e-6)

    @property
    def pending(self) -> int:
        return len(self._buf)

    def reset(self) -> None:
        self.stats.resync_bytes += len(self._buf)
        self._buf.clear()
        self._synced = False

    def feed(self, data: bytes | bytearray | memoryview) -> list[ChipFrame]:
        buf, st, n_len = self._buf, self.stats, self._len
        buf += data
        st.bytes_in += len(data)
        frames: list[ChipFrame] = []
        pos, n = 0, len(buf)
        while True:
            if self._synced:
                if n - pos < n_len:
                    break
                frame = self._frame_at(buf, pos)
                if frame is not None:
                    frames.append(frame)
                    pos += n_len
                    continue
                self._synced = False
                st.frame_errors += 1
                st.resync_bytes += 1
                pos += 1
            j = buf.find(EOL, pos)
            if j < 0:
                keep = 1 if n > pos and buf[n - 1] == EOL[0] else 0  # a CRLF may straddle two reads
                st.resync_bytes += n - keep - pos
                pos = n - keep
                break
            start = j + len(EOL)
            if n - start < 2 * n_len:  # wait for two frames to confirm this start
                st.resync_bytes += j - pos
                pos = j
                break
            first = self._frame_at(buf, start)
            second = self._frame_at(buf, start + n_len) if first is not None else None
            if second is None:
                st.resync_bytes += j + 1 - pos
                pos = j + 1
                continue
            st.resync_bytes += start - pos
            frames += (first, second)
            pos = start + 2 * n_len
            self._synced = True
        del buf[:pos]
        st.frames += len(frames)
        return frames

    def decode_record(self, raw: bytes) -> ChipFrame:
        if len(raw) != self._len:
            raise ProtocolError(f"an anyskin frame of {self.n_chips} chips is {self._len} bytes, got {len(raw)}")
        frame = self._frame_at(raw, 0)
        if frame is None:
            raise ProtocolError("not a valid anyskin frame (no CRLF at the end, or implausible values)")
        return frame

    def no_frame_hint(self) -> str:
        st = self.stats
        return (f"{st.bytes_in} bytes but no {self._len}-byte frame of {self.n_chips} chips x (t, x, y, z) float32 "
                f"+ CRLF ({st.frame_errors} refused): does the board run the binary burst sketch, and does the "
                "board layout have its chip count?")

    def _frame_at(self, buf: bytes | bytearray, start: int) -> ChipFrame | None:
        """The frame at ``start`` when it ends in CRLF and its values are plausible, else None."""
        end = start + self._len
        if buf[end - 2:end] != EOL:
            return None
        raw = bytes(buf[start:end])
        values = np.frombuffer(raw, _F32, 4 * self.n_chips).reshape(self.n_chips, 4)
        temps, field = values[:, 0], values[:, 1:]
        lo, hi = TEMPERATURE_RANGE_C
        # written so that NaN fails every comparison and infinity the last one: no separate finiteness pass
        if not (temps.min() >= lo and temps.max() <= hi and np.abs(field).max() <= MAX_FIELD_UT):
            return None
        return ChipFrame(field, np.abs(field) >= self._rail_ut, None, None, 0, temps, raw)



