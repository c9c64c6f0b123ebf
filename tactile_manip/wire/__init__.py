"""The boards' wire formats: one decoder per format, chosen by name (docs/design.md, Wire protocol).

Pure byte parsing on numpy and the core (chip settings), so the serial backend (:mod:`tactile_manip.sensors`)
and the recording reader (:mod:`tactile_manip.logs.recording`) share it; the SuperMag frame codec itself is
:mod:`tactile_manip.wire.protocol`.

:data:`WIRE_FORMATS` maps a name to its ``"module:Class"``; :func:`make_decoder` imports only the chosen one.

- ``supermag`` (default): our binary frames with sequence, device clock, status and CRC (``firmware/``);
- ``anyskin``: the published ReSkin/AnySkin binary burst sketch (float32 t, x, y, z per chip, then CRLF).
"""

from __future__ import annotations

import importlib

from tactile_manip.chips import ChipSettings
from tactile_manip.wire.base import ChipFrame, WireDecoder, WireStats

WIRE_FORMATS: dict[str, str] = {
    "supermag": "tactile_manip.wire.supermag:SuperMagDecoder",
    "anyskin": "tactile_manip.wire.anyskin:AnySkinDecoder",
}
DEFAULT_LAYOUTS: dict[str, str] = {"supermag": "supermag-4x4", "anyskin": "anyskin-5"}


def make_decoder(name: str, *, n_chips: int, chip: ChipSettings) -> WireDecoder:
    """A fresh decoder of the format ``name`` for ``n_chips`` chips; ValueError naming the known formats."""
    if name not in WIRE_FORMATS:
        raise ValueError(f"unknown wire format {name!r}; known formats: {', '.join(WIRE_FORMATS)}")
    module, _, cls = WIRE_FORMATS[name].partition(":")
    return getattr(importlib.import_module(module), cls)(n_chips=n_chips, chip=chip)


__all__ = ["DEFAULT_LAYOUTS", "WIRE_FORMATS", "ChipFrame", "WireDecoder", "WireStats", "make_decoder"]
