"""Multi-layer perceptrons applied to the last axis."""

from __future__ import annotations

from typing import Sequence

from torch import nn

#: LeakyReLU slope of every hidden activation (the value of DGCNN, whose EdgeConv the models use).
NEGATIVE_SLOPE = 0.2


def mlp(channels: Sequence[int], final_activation: bool = False) -> nn.Sequential:
    """Linear layers ``channels[0] -> channels[1] -> ... -> channels[-1]`` with LeakyReLU between
    them (and after the last one when ``final_activation``). ``channels`` needs at least two entries."""
    if len(channels) < 2:
        raise ValueError(f"an MLP needs input and output sizes, got {list(channels)}")
    layers: list[nn.Module] = []
    for i in range(len(channels) - 1):
        layers.append(nn.Linear(channels[i], channels[i + 1]))
        if i < len(channels) - 2 or final_activation:
            layers.append(nn.LeakyReLU(NEGATIVE_SLOPE))
    return nn.Sequential(*layers)
