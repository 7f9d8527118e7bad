"""Output reconstruction: a displacement as a magnitude times a direction (FitGar, Li et al. 2023, Sec. 4.2).

Instead of regressing a vertex displacement ``Delta_i in R^3`` directly, two branches predict its length
``|Delta_i| >= 0`` (fully connected layers, ReLU after each: FitGar Sec. 5.1) and its direction
``delta_i`` (fully connected layers, Tanh after each, then scaled to unit length), and FitGar Eq. 4
multiplies them: ``Delta_i = |Delta_i| * delta_i``. Here the magnitude is also multiplied by a fixed
``scale`` (metres, a statistic of the training displacements) so that the branch works near 1.
"""

from __future__ import annotations

from typing import Sequence

import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.models.layers.init import undrawn
from loosefit.models.layers.mlp import MLP

#: Directions shorter than this (before normalising) are treated as this long: no division by zero.
MIN_DIRECTION_NORM = 1e-6


def unit_direction(raw: torch.Tensor) -> torch.Tensor:
    """``raw (..., 3)`` -> unit vectors ``(..., 3)`` (a zero vector stays zero)."""
    return raw / raw.norm(dim=-1, keepdim=True).clamp_min(MIN_DIRECTION_NORM)


def compose_displacement(magnitude: torch.Tensor, direction: torch.Tensor) -> torch.Tensor:
    """FitGar Eq. 4: ``magnitude (..., 1)`` (>= 0) times unit ``direction (..., 3)`` -> ``(..., 3)``."""
    return magnitude * direction  # FitGar Eq. 4


class DecomposedOutput(nn.Module):
    """The two output branches' fully connected ends and FitGar Eq. 4.

    ``forward(magnitude_features (N, C_m), direction_features (N, C_d))`` returns a dict with
    ``displacement (N, 3)`` metres, ``magnitude (N, 1)`` metres (>= 0) and ``direction (N, 3)`` (unit).

    Args:
        magnitude_in, direction_in: feature sizes coming out of the two branches' graph layers.
        hidden: hidden sizes of both fully connected stacks (FitGar Sec. 5.1: coarse [256, 128],
            detail [128, 64]); they end in 1 (magnitude) and 3 (direction) outputs.
        scale: metres per unit of the magnitude branch.
        magnitude_bias: initial bias of the magnitude branch's last layer (positive: the ReLU starts
            open, so every vertex gets a gradient from the first step).

    Shapes:
        magnitude_features ``(N, magnitude_in)``, direction_features ``(N, direction_in)`` ->
        ``displacement (N, 3)``, ``magnitude (N, 1)``, ``direction (N, 3)``.
    """

    def __init__(self, magnitude_in: int, direction_in: int, hidden: Sequence[int], scale: float = 1.0,
                 magnitude_bias: float = 0.5):
        super().__init__()
        self.magnitude = undrawn(MLP, (magnitude_in, *hidden, 1), nn.ReLU, final_activation=True)
        self.direction = undrawn(MLP, (direction_in, *hidden, 3), nn.Tanh, final_activation=True)
        self.magnitude_bias = float(magnitude_bias)
        self.register_buffer("scale", torch.tensor(float(scale)))
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """The stacks' default initialisation (magnitude, then direction), the magnitude's last bias at
        ``magnitude_bias``."""
        self.magnitude.reset_parameters()
        self.direction.reset_parameters()
        with torch.no_grad():
            self.magnitude[-2].bias.fill_(self.magnitude_bias)

    def extra_repr(self) -> str:
        return f"scale={float(self.scale):g}, magnitude_bias={self.magnitude_bias:g}"

    def forward(self, magnitude_features: torch.Tensor, direction_features: torch.Tensor) -> dict[str, torch.Tensor]:
        magnitude = self.magnitude(magnitude_features) * self.scale
        direction = unit_direction(self.direction(direction_features))
        return {"displacement": compose_displacement(magnitude, direction), "magnitude": magnitude,
                "direction": direction}


#: Direct outputs of the paper's ablation (FitGar Sec. 5.3): ``"plain"`` (w/o decomposition, unbounded) and
#: ``"limited"`` (w/ output limit: within plus or minus a fixed limit).
DIRECT_MODES = ("plain", "limited")


class DirectOutput(nn.Module):
    """The ablations' output without FitGar Eq. 4: one branch's features ``(N, C)`` -> a displacement ``(N, 3)``.

    Fully connected layers ``(C, *hidden)`` with Tanh after each, then a linear layer to 3 values ``z``:
    ``"plain"`` gives ``scale * z``; ``"limited"`` gives ``limit * scale * tanh(z)``, every coordinate
    within plus or minus ``limit * scale`` (the paper limits to ``(-1, 1)`` after dividing by a factor of 5).
    Returns ``{"displacement": (N, 3)}`` metres.

    Shapes:
        features ``(N, in_channels)`` -> ``displacement (N, 3)``.
    """

    def __init__(self, in_channels: int, hidden: Sequence[int], mode: str, scale: float = 1.0, limit: float = 5.0):
        super().__init__()
        if mode not in DIRECT_MODES:
            raise InputError(f"direct output mode must be one of {DIRECT_MODES}, got {mode!r}")
        self.mode, self.limit = mode, float(limit)
        self.hidden = undrawn(MLP, (in_channels, *hidden), nn.Tanh, final_activation=True) if hidden else nn.Identity()
        self.out = undrawn(nn.Linear, hidden[-1] if hidden else in_channels, 3)
        self.register_buffer("scale", torch.tensor(float(scale)))
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """torch's default initialisation of the hidden layers, then of the read-out."""
        if isinstance(self.hidden, MLP):
            self.hidden.reset_parameters()
        self.out.reset_parameters()

    def extra_repr(self) -> str:
        return f"mode={self.mode!r}, scale={float(self.scale):g}, limit={self.limit:g}"

    def forward(self, features: torch.Tensor) -> dict[str, torch.Tensor]:
        z = self.out(self.hidden(features))
        if self.mode == "limited":
            return {"displacement": self.limit * self.scale * torch.tanh(z)}
        return {"displacement": self.scale * z}
