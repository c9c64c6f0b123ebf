"""Moved to :mod:`tactile_manip.evaluation.contact`; this name stays importable."""
import sys
from tactile_manip.evaluation import contact as _moved
sys.modules[__name__] = _moved
