"""The ReSkin/AnySkin wire format under its former path: the code lives in :mod:`tactile_manip.wire.anyskin`,
and this module names the same objects.
"""

from tactile_manip.wire.anyskin import (
    CHIP_BYTES,
    EOL,
    MAX_FIELD_UT,
    TEMPERATURE_RANGE_C,
    AnySkinDecoder,
    frame_length,
    pack_frame,
)

__all__ = ["CHIP_BYTES", "EOL", "MAX_FIELD_UT", "TEMPERATURE_RANGE_C", "AnySkinDecoder", "frame_length",
           "pack_frame"]
