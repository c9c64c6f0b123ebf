"""The checks every small network's training config shares (the contact model, the angle head)."""

from __future__ import annotations

import math
from typing import Any


def check_schedule(cfg: Any) -> None:
    """Refuse (ValueError) epochs, batch size or patience below 1, a learning rate outside (0, 1) or a negative
    weight decay on ``cfg`` (a dataclass with those fields)."""
    for name in ("epochs", "batch_size", "patience"):
        if getattr(cfg, name) < 1:
            raise ValueError(f"{name} must be >= 1, got {getattr(cfg, name)}")
    if not (math.isfinite(cfg.lr) and 0 < cfg.lr < 1):
        raise ValueError(f"lr must be in (0, 1), got {cfg.lr}")
    if not (math.isfinite(cfg.weight_decay) and cfg.weight_decay >= 0):
        raise ValueError(f"weight_decay must be >= 0, got {cfg.weight_decay}")
