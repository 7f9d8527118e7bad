"""A recurrent head: a GRU over a sequence of feature vectors followed by a linear read-out."""

from __future__ import annotations

import torch
from torch import nn

from loosefit.models.layers.gru_bptt import gru_bptt
from loosefit.models.layers.init import undrawn


class GRUHead(nn.Module):
    """``x (B, T, in) -> y (B, T, out)`` through ``layers`` GRU layers of ``hidden`` units and a linear layer.

    The hidden state ``h (layers, B, hidden)`` is returned and accepted, so running ``T`` frames at once
    or one frame at a time, passing ``h`` along, gives the same outputs (``h=None`` is the zero state).

    Args:
        in_features, hidden, out_features: sizes.
        layers: stacked GRU layers.
        out_scale: factor applied to the read-out's initial weights and bias; below 1 starts the
            outputs near zero, which suits outputs that are residuals on a rest state.

    Shapes:
        x ``(B, T, in_features)``, h ``(layers, B, hidden)`` or None -> y ``(B, T, out_features)``, h
        ``(layers, B, hidden)``.
    """

    def __init__(self, in_features: int, hidden: int, out_features: int, layers: int = 1, out_scale: float = 1.0):
        super().__init__()
        self.gru = undrawn(nn.GRU, in_features, hidden, num_layers=layers, batch_first=True)
        self.out = undrawn(nn.Linear, hidden, out_features)
        self.out_scale = float(out_scale)
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """torch's default initialisation of the GRU, then of the read-out, scaled by ``out_scale``."""
        self.gru.reset_parameters()
        self.out.reset_parameters()
        with torch.no_grad():
            self.out.weight.mul_(self.out_scale)
            self.out.bias.mul_(self.out_scale)

    def extra_repr(self) -> str:
        return f"out_scale={self.out_scale:g}"

    def forward(self, x: torch.Tensor, h: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """``x (B, T, in)``, ``h (layers, B, hidden)`` or None -> ``(y (B, T, out), h after frame T-1)``."""
        seq, h = gru_bptt(self.gru, x, h)  # torch's GRU, with a backward pass twice as fast on the CPU
        return self.out(seq), h
