"""Moved to :mod:`tactile_manip.learning.cvae.data`; this name stays importable."""
import sys
from tactile_manip.learning.cvae import data as _moved
sys.modules[__name__] = _moved
