"""Moved to :mod:`tactile_manip.learning.contact.train`; this name stays importable."""
import sys
from tactile_manip.learning.contact import train as _moved
sys.modules[__name__] = _moved
