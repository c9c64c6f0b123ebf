"""The wire-decoder interface under its former path: the code lives in :mod:`tactile_manip.wire.base`, and this
module names the same objects.
"""

from tactile_manip.wire.base import ChipFrame, WireDecoder, WireStats

__all__ = ["ChipFrame", "WireDecoder", "WireStats"]
