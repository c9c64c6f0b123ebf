"""Moved to :mod:`tactile_manip.learning.angle_head.export`; this name stays importable."""
import sys
from tactile_manip.learning.angle_head import export as _moved
sys.modules[__name__] = _moved
