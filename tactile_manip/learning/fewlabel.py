"""Moved to :mod:`tactile_manip.learning.contact.fewlabel`; this name stays importable."""
import sys
from tactile_manip.learning.contact import fewlabel as _moved
sys.modules[__name__] = _moved
