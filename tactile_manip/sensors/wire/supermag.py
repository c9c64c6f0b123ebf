"""The SuperMag wire format under its former path: the code lives in :mod:`tactile_manip.wire.supermag`, and
this module names the same objects.
"""

from tactile_manip.wire.supermag import SuperMagDecoder

__all__ = ["SuperMagDecoder"]
