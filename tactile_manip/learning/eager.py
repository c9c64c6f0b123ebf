"""Moved to :mod:`tactile_manip.learning.cvae.eager`; this name stays importable."""
import sys
from tactile_manip.learning.cvae import eager as _moved
sys.modules[__name__] = _moved
