"""Moved to :mod:`tactile_manip.learning.contact.model`; this name stays importable."""
import sys
from tactile_manip.learning.contact import model as _moved
sys.modules[__name__] = _moved
