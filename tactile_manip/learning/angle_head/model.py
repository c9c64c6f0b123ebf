"""The angle head: the contact's in-plane axis read straight from one magnetic reading, with its uncertainty.

Input ``field_ut`` (B, R, C, A) float32, one board's reading (uT, baseline-subtracted). Output ``axis`` (B, 2):
the vector ``kappa (cos 2t, sin 2t)`` of a von Mises distribution over the doubled axis angle ``2t`` (an axis
is defined modulo 180 deg, so ``2t`` is a proper angle): its direction is the estimate, half its argument the
axis angle ``t``, and its length ``kappa`` the concentration, large where the reading pins the axis down and
near 0 where it does not (a round contact, a faint press). Trained by the von Mises negative log-likelihood,
the length is the network's own uncertainty, in the same units for every reading.

Features, computed inside the network so that training, export and the runtime cannot differ: the reading's
direction (the 48 values over their norm: the pattern, which carries the contact's shape and pose) and the
log10 of its norm (how hard it presses), standardised with the training split's mean and spread, stored as
buffers with the weights. A press at another force scales the field but keeps most of its pattern.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import torch
from torch import nn

ACTIVATIONS = {"gelu": nn.GELU, "relu": nn.ReLU, "silu": nn.SiLU}
NORM_FLOOR_UT = 1e-3  # added to the reading's norm before the division and the log: an all-zero reading is finite


@dataclass(frozen=True)
class AngleModelConfig:
    """Architecture of :class:`AngleHead` (the shape is filled in from the dataset)."""

    cells: tuple[int, int, int] = (4, 4, 3)   # (R, C, A) of one reading
    hidden: int = 256                         # units per hidden layer
    layers: int = 3                           # hidden layers
    act: Literal["gelu", "relu", "silu"] = "gelu"

    def __post_init__(self) -> None:
        if len(self.cells) != 3 or min(self.cells) < 1:
            raise ValueError(f"cells must be (rows, cols, channels) >= 1, got {self.cells}")
        for name in ("hidden", "layers"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.act not in ACTIVATIONS:
            raise ValueError(f"act must be one of {tuple(ACTIVATIONS)}, got {self.act!r}")

    @property
    def features(self) -> int:
        r, c, a = self.cells
        return r * c * a + 1


def reading_features(field_ut: torch.Tensor) -> torch.Tensor:
    """(B, R*C*A + 1): the reading over its norm, and log10 of the norm (uT)."""
    flat = field_ut.reshape(field_ut.shape[0], -1)
    norm = torch.sqrt((flat * flat).sum(dim=1, keepdim=True)) + NORM_FLOOR_UT
    return torch.cat([flat / norm, torch.log10(norm)], dim=1)


class AngleHead(nn.Module):
    """MLP from the standardised features to the von Mises vector ``axis`` (see the module docstring)."""

    def __init__(self, cfg: AngleModelConfig) -> None:
        super().__init__()
        self.cfg = cfg
        width, layers = cfg.features, []
        for _ in range(cfg.layers):
            layers += [nn.Linear(width, cfg.hidden), ACTIVATIONS[cfg.act]()]
            width = cfg.hidden
        layers.append(nn.Linear(width, 2))
        self.mlp = nn.Sequential(*layers)
        self.register_buffer("feature_mean", torch.zeros(cfg.features))
        self.register_buffer("feature_std", torch.ones(cfg.features))

    def set_normalisation(self, features: torch.Tensor) -> None:
        """Standardise with these training features' mean and spread (a constant feature keeps spread 1)."""
        std = features.std(dim=0)
        self.feature_mean.copy_(features.mean(dim=0))
        self.feature_std.copy_(torch.where(std > 1e-6, std, torch.ones_like(std)))

    def forward(self, field_ut: torch.Tensor) -> torch.Tensor:
        x = (reading_features(field_ut) - self.feature_mean) / self.feature_std
        return self.mlp(x)


class SymmetrizedAngleHead(nn.Module):
    """A trained head read over the board's symmetries: each reading's symmetric copies go through the head,
    each copy's axis is turned back, and the mean is the axis. The head learnt the symmetries from augmented
    data and holds them only approximately; the mean holds them exactly and averages out some of the head's
    own error, at the cost of one batch of copies per reading. Where the copies disagree, the mean's length
    (its ``kappa``) shrinks, so the concentration says so.

    Args:
        head: the trained head.
        reading_maps: (S, N, N) the linear map of each symmetry on the flattened reading (N = R * C * A).
        axis_maps: (S, 2, 2) the map turning a copy's (cos 2t, sin 2t) back to the reading's.
    """

    def __init__(self, head: AngleHead, reading_maps: torch.Tensor, axis_maps: torch.Tensor) -> None:
        super().__init__()
        self.head, self.cfg = head, head.cfg
        self.register_buffer("reading_maps", reading_maps.to(torch.float32))
        self.register_buffer("axis_maps", axis_maps.to(torch.float32))

    def forward(self, field_ut: torch.Tensor) -> torch.Tensor:
        batch, copies = field_ut.shape[0], self.reading_maps.shape[0]
        flat = field_ut.reshape(1, batch, -1)
        turned = torch.matmul(flat, self.reading_maps.transpose(1, 2))            # (S, B, N)
        axes = self.head(turned.reshape(copies * batch, *self.cfg.cells)).reshape(copies, batch, 2)
        return torch.matmul(axes, self.axis_maps.transpose(1, 2)).mean(dim=0)     # (B, 2)


def von_mises_nll(axis: torch.Tensor, angle_rad: torch.Tensor) -> torch.Tensor:
    """Per-sample negative log-likelihood of the axis angles ``angle_rad`` (B,) under the von Mises of the
    doubled angle whose natural parameter is ``axis`` (B, 2) (constant log 2 pi left out)."""
    kappa = torch.linalg.vector_norm(axis, dim=1)
    fit = axis[:, 0] * torch.cos(2 * angle_rad) + axis[:, 1] * torch.sin(2 * angle_rad)
    return torch.log(torch.special.i0e(kappa)) + kappa - fit


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
