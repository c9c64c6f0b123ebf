"""Moved to :mod:`tactile_manip.learning.contact.export`; this name stays importable."""
import sys
from tactile_manip.learning.contact import export as _moved
sys.modules[__name__] = _moved
