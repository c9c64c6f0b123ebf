"""Moved to :mod:`tactile_manip.evaluation.contact_baselines`; this name stays importable."""
import sys
from tactile_manip.evaluation import contact_baselines as _moved
sys.modules[__name__] = _moved
