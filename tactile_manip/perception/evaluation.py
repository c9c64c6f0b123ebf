"""Moved to :mod:`tactile_manip.evaluation.images`; this name stays importable."""
import sys
from tactile_manip.evaluation import images as _moved
sys.modules[__name__] = _moved
