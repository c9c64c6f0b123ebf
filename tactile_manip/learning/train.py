"""Moved to :mod:`tactile_manip.learning.cvae.train`; this name stays importable."""
import sys
from tactile_manip.learning.cvae import train as _moved
sys.modules[__name__] = _moved
