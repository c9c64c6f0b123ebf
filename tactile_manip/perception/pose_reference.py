"""Moved to :mod:`tactile_manip.evaluation.pose_reference`; this name stays importable."""
import sys
from tactile_manip.evaluation import pose_reference as _moved
sys.modules[__name__] = _moved
