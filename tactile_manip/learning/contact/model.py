"""The contact network: a short window of magnetic readings in, contact targets with a sigma each out.

Input ``field_ut`` (B, T, R, C, A) float32: T frames of one board's reading (R x C cells of A channels, uT,
baseline-subtracted), frame 0 the newest and frame k the reading k frames before it (T =
``context_frames``; elastomers have hysteresis, so the last few frames tell loading from unloading). Output
``mean`` (B, K) and ``sigma`` (B, K) in the targets' units (``x_mm``, ``force_n``, ...).

Features, computed inside the network so that training, export and the runtime cannot differ: the newest
frame's values, with ``features = "field_direction"`` also their direction (the frame divided by its norm)
and log norm (a press at another depth scales the field but keeps its pattern, so the direction carries the
position and the norm the depth and force), and the change from each older frame to the newest. They are
standardised with the training split's mean and spread, stored as buffers with the weights.

Each of ``members`` independently initialised MLPs predicts a Gaussian (mean, log variance) per target; the
output is their mixture: the mean of the means, and sigma from the mean variance plus the variance of the
means (the members' disagreement adds the uncertainty a single variance head misses), times a per-target
``sigma_scale`` that training fits on the validation samples so that 68.3 % of their errors fall within one
sigma (recalibration after Kuleshov et al. 2018; 1 until fitted).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import torch
from torch import nn

from tactile_manip.config import check_ranges

FEATURES = ("field", "field_direction")
ACTIVATIONS = {"gelu": nn.GELU, "relu": nn.ReLU, "silu": nn.SiLU}
LOG_VAR_LIMIT = 12.0  # clamp of the standardised log variance: sigma within e^-6 .. e^6 target spreads
# allowed sizes: far above the shipped configs (3 frames, 128 units, 3 layers, 5 members), low enough that a typo
# fails at once (a million frames of context would allocate gigabytes)
SIZE_RANGES = {"targets": (1, 256), "context_frames": (1, 64), "hidden": (1, 4096), "layers": (1, 16),
               "members": (1, 32)}


@dataclass(frozen=True)
class ContactModelConfig:
    """Architecture of :class:`ContactModel` (``[model]`` of ``configs/train/contact.toml``; the shape fields
    are filled in from the dataset)."""

    cells: tuple[int, int, int] = (3, 3, 3)   # (R, C, A) of one reading
    targets: int = 1                          # K, outputs per sample
    context_frames: int = 3                   # T: the newest reading and T - 1 before it
    features: Literal["field", "field_direction"] = "field_direction"
    hidden: int = 128                         # units per hidden layer
    layers: int = 3                           # hidden layers
    act: Literal["gelu", "relu", "silu"] = "gelu"
    members: int = 5                          # ensemble members

    def __post_init__(self) -> None:
        if len(self.cells) != 3 or min(self.cells) < 1:
            raise ValueError(f"cells must be (rows, cols, channels) >= 1, got {self.cells}")
        check_ranges(self, SIZE_RANGES)
        if self.features not in FEATURES:
            raise ValueError(f"features must be one of {FEATURES}, got {self.features!r}")
        if self.act not in ACTIVATIONS:
            raise ValueError(f"act must be one of {tuple(ACTIVATIONS)}, got {self.act!r}")

    @property
    def frame_values(self) -> int:
        """Values in one frame, R * C * A."""
        r, c, a = self.cells
        return r * c * a

    @property
    def feature_count(self) -> int:
        """Features per sample (see the module docstring)."""
        per_frame = self.frame_values
        direction = per_frame + 1 if self.features == "field_direction" else 0
        return per_frame + direction + per_frame * (self.context_frames - 1)


def frame_features(field_ut: torch.Tensor, cfg: ContactModelConfig) -> torch.Tensor:
    """Raw features (B, F) of ``field_ut`` (B, T, R, C, A) uT, before standardisation."""
    x = field_ut.flatten(2)                                  # (B, T, R*C*A)
    newest = x[:, 0]                                         # (B, R*C*A)
    parts = [newest]
    if cfg.features == "field_direction":
        norm = torch.linalg.vector_norm(newest, dim=1, keepdim=True)   # (B, 1)
        parts += [newest / norm.clamp_min(1e-3), torch.log1p(norm)]
    parts += [newest - x[:, k] for k in range(1, cfg.context_frames)]
    return torch.cat(parts, dim=1)                           # (B, F)


class GaussianMLP(nn.Module):
    """One member: features (B, F) standardised -> mean (B, K) and log variance (B, K), standardised targets."""

    def __init__(self, cfg: ContactModelConfig) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        width = cfg.feature_count
        for _ in range(cfg.layers):
            layers += [nn.Linear(width, cfg.hidden), ACTIVATIONS[cfg.act]()]
            width = cfg.hidden
        self.body = nn.Sequential(*layers)
        self.head = nn.Linear(width, 2 * cfg.targets)
        self.targets = cfg.targets

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.head(self.body(features))                 # (B, 2K)
        log_var = out[:, self.targets:].clamp(-LOG_VAR_LIMIT, LOG_VAR_LIMIT)
        return out[:, :self.targets], log_var


class ContactModel(nn.Module):
    """Readings window (B, T, R, C, A) uT -> target mean (B, K) and sigma (B, K) in target units."""

    def __init__(self, cfg: ContactModelConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.members = nn.ModuleList(GaussianMLP(cfg) for _ in range(cfg.members))
        self.register_buffer("feature_offset", torch.zeros(cfg.feature_count))
        self.register_buffer("feature_scale", torch.ones(cfg.feature_count))
        self.register_buffer("target_offset", torch.zeros(cfg.targets))
        self.register_buffer("target_scale", torch.ones(cfg.targets))
        self.register_buffer("sigma_scale", torch.ones(cfg.targets))

    def set_normalisation(self, features: torch.Tensor, targets: torch.Tensor) -> None:
        """Standardise with the mean and spread of training ``features`` (N, F) and ``targets`` (N, K);
        a constant feature (an unused cell of the board) keeps scale 1."""
        spread = features.std(0)
        self.feature_offset.copy_(features.mean(0))
        self.feature_scale.copy_(torch.where(spread > 1e-6, spread, torch.ones_like(spread)))
        tspread = targets.std(0)
        self.target_offset.copy_(targets.mean(0))
        self.target_scale.copy_(torch.where(tspread > 1e-9, tspread, torch.ones_like(tspread)))

    def standardised_features(self, field_ut: torch.Tensor) -> torch.Tensor:
        """Features (B, F) of ``field_ut`` (B, T, R, C, A), standardised with the training split's statistics."""
        return (frame_features(field_ut, self.cfg) - self.feature_offset) / self.feature_scale

    def forward(self, field_ut: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        z = self.standardised_features(field_ut)
        outs = [m(z) for m in self.members]
        means = torch.stack([o[0] for o in outs])            # (M, B, K), standardised
        variances = torch.stack([o[1].exp() for o in outs])  # (M, B, K)
        mean = means.mean(0)
        var = variances.mean(0) + ((means - mean) ** 2).mean(0)
        return self.target_offset + self.target_scale * mean, self.target_scale * self.sigma_scale * var.sqrt()


class FusedContactModel(nn.Module):
    """The same function as a trained :class:`ContactModel`, with the members' layers stacked into batched
    matrix products (one node per layer instead of one per member and layer) and the feature standardisation
    folded into the first layer's weights: what the exported graph runs."""

    def __init__(self, model: ContactModel) -> None:
        super().__init__()
        self.cfg = model.cfg
        linears = [[m for m in member.body if isinstance(m, nn.Linear)] + [member.head] for member in model.members]
        weights = [torch.stack([ms[i].weight.detach().T for ms in linears]) for i in range(len(linears[0]))]
        biases = [torch.stack([ms[i].bias.detach()[None] for ms in linears]) for i in range(len(linears[0]))]
        # ((f - offset) / scale) @ W + b  ==  f @ (W / scale) + (b - (offset / scale) @ W)
        scale, offset = model.feature_scale.detach(), model.feature_offset.detach()
        biases[0] = biases[0] - ((offset / scale) @ weights[0])[:, None, :]   # (M, 1, H)
        weights[0] = weights[0] / scale[None, :, None]                  # (M, F, H)
        self.weights = nn.ParameterList(nn.Parameter(w, requires_grad=False) for w in weights)   # (M, in, out)
        self.biases = nn.ParameterList(nn.Parameter(b, requires_grad=False) for b in biases)     # (M, 1, out)
        self.act = ACTIVATIONS[self.cfg.act]()
        for name in ("target_offset", "target_scale", "sigma_scale"):
            self.register_buffer(name, getattr(model, name).detach().clone())

    def forward(self, field_ut: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = frame_features(field_ut, self.cfg).unsqueeze(0)  # (1, B, F), broadcast over the M members
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            h = torch.matmul(h, w) + b                       # (M, B, out)
            if i < len(self.weights) - 1:
                h = self.act(h)
        k = self.cfg.targets
        means = h[..., :k]                                   # (M, B, K)
        variances = h[..., k:].clamp(-LOG_VAR_LIMIT, LOG_VAR_LIMIT).exp()
        mean = means.mean(0)
        var = variances.mean(0) + ((means - mean) ** 2).mean(0)
        return self.target_offset + self.target_scale * mean, self.target_scale * self.sigma_scale * var.sqrt()


def count_parameters(model: nn.Module) -> int:
    """Trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
