"""Moved to :mod:`tactile_manip.learning.cvae.export`; this name stays importable."""
import sys
from tactile_manip.learning.cvae import export as _moved
sys.modules[__name__] = _moved
