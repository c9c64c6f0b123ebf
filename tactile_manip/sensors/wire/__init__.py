"""The wire formats under their former path: the decoders live in :mod:`tactile_manip.wire` (below the sensors
layer, so the recording reader and the data layer use them without the sensors), and this package and its
modules (``base``, ``anyskin``, ``supermag``) name the same objects.
"""

from tactile_manip.wire import DEFAULT_LAYOUTS, WIRE_FORMATS, ChipFrame, WireDecoder, WireStats, make_decoder

__all__ = ["DEFAULT_LAYOUTS", "WIRE_FORMATS", "ChipFrame", "WireDecoder", "WireStats", "make_decoder"]
