"""The SuperMag frame codec under its former path: the code lives in :mod:`tactile_manip.wire.protocol` (the
wire formats sit below the sensors layer, so the recording reader and the data layer use them without the
sensors), and this module names the same objects.
"""

from tactile_manip.wire.protocol import (
    CRC,
    FIELD_LEN,
    FLAG_TEMPERATURE,
    FRAME_LEN,
    FRAME_LEN_T,
    GRID,
    HEADER,
    HEADER_LEN,
    N_CHIPS,
    SYNC,
    TEMPERATURE_LEN,
    TEMPERATURE_LSB_C,
    VERSION,
    CountScale,
    DecoderStats,
    Frame,
    FrameDecoder,
    Unwrapper,
    crc16,
    decode_frame,
    encode_frame,
    frame_length,
)

__all__ = ["CRC", "FIELD_LEN", "FLAG_TEMPERATURE", "FRAME_LEN", "FRAME_LEN_T", "GRID", "HEADER", "HEADER_LEN",
           "N_CHIPS", "SYNC", "TEMPERATURE_LEN", "TEMPERATURE_LSB_C", "VERSION", "CountScale", "DecoderStats", "Frame",
           "FrameDecoder", "Unwrapper", "crc16", "decode_frame", "encode_frame", "frame_length"]
