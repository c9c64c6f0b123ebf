"""What every small network's training shares (the contact model, the angle head): config checks, one step."""

from __future__ import annotations

import math
from typing import Any

import torch

from tactile_manip.config import check_ranges
from tactile_manip.learning.cvae.train import SCHEDULE_RANGES, TrainingError


def check_schedule(cfg: Any) -> None:
    """Refuse epochs, batch size or patience outside :data:`~tactile_manip.learning.cvae.train.SCHEDULE_RANGES`
    (ConfigError), a learning rate outside (0, 1) or a negative weight decay (ValueError) on ``cfg`` (a dataclass
    with those fields)."""
    check_ranges(cfg, SCHEDULE_RANGES)
    if not (math.isfinite(cfg.lr) and 0 < cfg.lr < 1):
        raise ValueError(f"lr must be in (0, 1), got {cfg.lr}")
    if not (math.isfinite(cfg.weight_decay) and cfg.weight_decay >= 0):
        raise ValueError(f"weight_decay must be >= 0, got {cfg.weight_decay}")


def optimise_step(loss: torch.Tensor, opt: torch.optim.Optimizer, sched: Any, epoch: int, *, hint: str = "lower lr"
                  ) -> float:
    """Back-propagate ``loss``, step the optimiser and the per-step schedule, and return the loss; a non-finite
    loss raises :class:`TrainingError` naming the epoch, the learning rate and ``hint``."""
    if not torch.isfinite(loss):
        raise TrainingError(f"training diverged: the loss became {float(loss)} in epoch {epoch} "
                            f"(lr {sched.get_last_lr()[0]:g}); {hint}")
    opt.zero_grad(set_to_none=True)
    loss.backward()
    opt.step()
    sched.step()
    return float(loss.detach())
