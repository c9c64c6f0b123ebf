"""Moved to :mod:`tactile_manip.learning.angle_head.train`; this name stays importable."""
import sys
from tactile_manip.learning.angle_head import train as _moved
sys.modules[__name__] = _moved
