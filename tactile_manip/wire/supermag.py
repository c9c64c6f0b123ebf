"""The SuperMag wire format (docs/design.md, spoken by ``firmware/``) behind the :class:`WireDecoder` interface.

The codec itself is :mod:`tactile_manip.wire.protocol`; this adapter converts its raw counts to
microtesla with the chip's LSBs and hands the 16 chips on in firmware (row-major) order.
"""

from __future__ import annotations

import numpy as np

from tactile_manip.chips import MLX90393, ChipSettings
from tactile_manip.wire.protocol import (
    N_CHIPS,
    TEMPERATURE_LSB_C,
    VERSION,
    CountScale,
    Frame,
    FrameDecoder,
    decode_frame,
)
from tactile_manip.wire.base import ChipFrame, WireDecoder


class SuperMagDecoder(WireDecoder):
    """Binary frames with sync, sequence, device clock, status and CRC-16; 16 chips of raw int16 counts."""

    name = "supermag"
    seq_bits = 16
    clock_bits = 32

    def __init__(self, *, n_chips: int = N_CHIPS, chip: ChipSettings | None = None) -> None:
        if n_chips != N_CHIPS:
            raise ValueError(f"the supermag wire format carries {N_CHIPS} chips, the board layout has {n_chips}")
        super().__init__(n_chips=n_chips, chip=chip or MLX90393)
        self._frames = FrameDecoder()
        self.stats = self._frames.stats  # the codec's counters, shared
        self._scale = CountScale.from_chip(self.chip)
        self._rail = self._scale.saturation_counts

    @property
    def pending(self) -> int:
        return self._frames.pending

    def feed(self, data: bytes | bytearray | memoryview) -> list[ChipFrame]:
        return [self._convert(f) for f in self._frames.feed(data)]

    def reset(self) -> None:
        self._frames.reset()

    def decode_record(self, raw: bytes) -> ChipFrame:
        return self._convert(decode_frame(raw))

    def no_frame_hint(self) -> str:
        st = self.stats
        if st.version_errors > st.crc_errors:
            return (f"{st.bytes_in} bytes but {st.version_errors} frames of another protocol version: update the "
                    f"firmware or tactile_manip so both speak version {VERSION}")
        return (f"{st.bytes_in} bytes but no valid frame ({st.crc_errors} CRC errors): is the baud rate right, "
                "is this the sensor's port, and does the board speak this wire format (`wire_format`)?")

    def _convert(self, f: Frame) -> ChipFrame:
        counts = f.counts.reshape(N_CHIPS, 3)
        temps = None
        if f.temperature_raw is not None:
            temps = f.temperature_raw.reshape(N_CHIPS) * np.float32(TEMPERATURE_LSB_C)
        return ChipFrame(self._scale.to_ut(counts), (counts >= self._rail) | (counts <= -self._rail), f.seq,
                         f.t_mcu_us, f.status, temps, f.raw)

