"""The test tree itself: pytest's default import mode needs every test module's basename to be unique."""

from collections import Counter
from pathlib import Path


def test_test_module_basenames_are_unique():
    names = Counter(p.name for p in Path(__file__).resolve().parent.rglob("test_*.py"))
    repeated = sorted(n for n, c in names.items() if c > 1)
    assert not repeated, f"{repeated}: rename one of each, pytest cannot import both"
