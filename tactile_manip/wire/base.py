"""What every wire-format decoder of the serial backend provides (the formats: :mod:`tactile_manip.wire`).

A decoder turns the bytes a port delivers into :class:`ChipFrame` s: one field per chip, in firmware order
and chip axes, in microtesla. The board layout (:class:`~tactile_manip.boards.Board`) later maps the chips
onto reading cells. A decoder never raises on bad bytes: it skips them and counts them in its
:class:`WireStats`, and its output does not depend on how the stream was chunked.
"""

from __future__ import annotations

import abc
from typing import ClassVar, NamedTuple

import numpy as np

from tactile_manip.chips import ChipSettings
from tactile_manip.wire.protocol import DecoderStats as WireStats

__all__ = ["ChipFrame", "WireDecoder", "WireStats"]


class ChipFrame(NamedTuple):
    """One decoded frame of any wire format.

    Attributes:
        field_ut: (n_chips, 3) float32 field per chip, chip axes, uT (read-only).
        saturated: (n_chips, 3) bool, channels at the rail.
        seq: the wire's frame counter (not unwrapped), or None where the format has none (the host counts).
        t_device_us: device clock in us (not unwrapped), or None where the format has none.
        status: device status bits (0 where the format has none).
        temperature_c: (n_chips,) float32 chip temperatures, or None.
        raw: the frame's bytes exactly as received (what a recorder stores).
    """

    field_ut: np.ndarray
    saturated: np.ndarray
    seq: int | None
    t_device_us: int | None
    status: int
    temperature_c: np.ndarray | None
    raw: bytes


class WireDecoder(abc.ABC):
    """A stream decoder for one wire format.

    Args:
        n_chips: chips per frame (from the board layout).
        chip: chip settings (LSBs and rail) for formats that send raw counts.
    """

    name: ClassVar[str]
    seq_bits: ClassVar[int | None]    # width of the wire's frame counter, None when it has none
    clock_bits: ClassVar[int | None]  # width of the wire's device clock (us), None when it has none

    def __init__(self, *, n_chips: int, chip: ChipSettings) -> None:
        self.n_chips = n_chips
        self.chip = chip
        self.stats = WireStats()

    @property
    @abc.abstractmethod
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame."""

    @abc.abstractmethod
    def feed(self, data: bytes | bytearray | memoryview) -> list[ChipFrame]:
        """Append ``data``; return every complete, valid frame now available, oldest first. Never raises."""

    @abc.abstractmethod
    def reset(self) -> None:
        """Forget buffered bytes (after a port was reopened); they count as resync bytes."""

    @abc.abstractmethod
    def decode_record(self, raw: bytes) -> ChipFrame:
        """Decode one stored frame (``ChipFrame.raw``); ProtocolError naming what is wrong."""

    @abc.abstractmethod
    def no_frame_hint(self) -> str:
        """Why bytes arrived but no frame did, from the counters (for the connect timeout message)."""
