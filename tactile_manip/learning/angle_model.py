"""Moved to :mod:`tactile_manip.learning.angle_head.model`; this name stays importable."""
import sys
from tactile_manip.learning.angle_head import model as _moved
sys.modules[__name__] = _moved
