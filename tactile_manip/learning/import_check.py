"""Clear errors for missing optional packages of the learning stack."""

from __future__ import annotations


def require_torch() -> None:
    """Raise ImportError naming the install command when torch is missing."""
    try:
        import torch  # noqa: F401
    except ImportError as e:
        raise ImportError('training needs torch: pip install torch==2.13.0 && pip install -e ".[train]"') from e
