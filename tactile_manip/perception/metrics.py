"""Moved to :mod:`tactile_manip.evaluation.metrics`; this name stays importable."""
import sys
from tactile_manip.evaluation import metrics as _moved
sys.modules[__name__] = _moved
