"""Multi-layer perceptrons applied to the last axis: the one fully connected stack of every model."""

from __future__ import annotations

from typing import Callable, Sequence

from torch import nn

from loosefit.errors import InputError
from loosefit.models.layers.init import undrawn

#: LeakyReLU slope of every hidden activation (the value of DGCNN, whose EdgeConv the models use).
NEGATIVE_SLOPE = 0.2


def leaky_relu() -> nn.Module:
    """The default activation of :class:`MLP`: LeakyReLU with slope :data:`NEGATIVE_SLOPE`."""
    return nn.LeakyReLU(NEGATIVE_SLOPE)


class MLP(nn.Sequential):
    """Linear layers ``channels[0] -> channels[1] -> ... -> channels[-1]`` with an activation between them
    (and after the last one when ``final_activation``).

    The modules are numbered as in ``nn.Sequential`` (linear layers at even indices, activations at odd ones),
    so ``state_dict`` keys read ``0.weight``, ``2.bias``, ...; weights are torch's ``nn.Linear`` defaults
    (Kaiming-uniform weight, uniform bias), drawn layer after layer.

    Args:
        channels: at least two sizes.
        activation: a function making the activation module (``nn.ReLU``, ``nn.Tanh``, ...); LeakyReLU with
            slope :data:`NEGATIVE_SLOPE` by default.
        final_activation: also after the last linear layer.

    Shapes:
        input ``(..., channels[0])`` -> output ``(..., channels[-1])``.
    """

    def __init__(self, channels: Sequence[int], activation: Callable[[], nn.Module] = leaky_relu,
                 final_activation: bool = False):
        if len(channels) < 2:
            raise InputError(f"an MLP needs input and output sizes, got {list(channels)}")
        layers: list[nn.Module] = []
        for i, (a, b) in enumerate(zip(channels[:-1], channels[1:])):
            layers.append(undrawn(nn.Linear, a, b))
            if i < len(channels) - 2 or final_activation:
                layers.append(activation())
        super().__init__(*layers)
        self.channels, self.final_activation = tuple(int(c) for c in channels), final_activation
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """torch's default initialisation of each linear layer, first to last."""
        for layer in self:
            if isinstance(layer, nn.Linear):
                layer.reset_parameters()

    def extra_repr(self) -> str:
        return f"channels={list(self.channels)}, final_activation={self.final_activation}"
