"""Clear errors for missing optional packages of the learning stack."""

from __future__ import annotations

from tactile_manip.extras import require


def require_torch() -> None:
    """Raise ImportError naming the install command when torch is missing."""
    require("torch", "training and export")
