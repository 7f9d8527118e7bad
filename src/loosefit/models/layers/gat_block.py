"""A graph-attention block with a self-reinforced stream (FitGar, Li et al. 2023, Sec. 4.3).

Two streams read the same node features ``x (N, C_in)`` and their outputs are concatenated:

- aggregation stream: multi-head graph attention (GAT, Velickovic et al. 2018, PyG's ``GATConv``) over
  the graph's edges plus a self loop per node. Head ``k`` gives
  ``a_i^k = sum_{j in N(i) + i} att_ij^k W^k x_j + b^k`` with attention weights ``att_ij^k`` (softmax over
  the neighbours of ``i``, summing to 1); the ``heads`` outputs are concatenated;
- self stream: one linear map of the node's own features, ``s_i = W_s x_i + b_s``.

Output ``[s_i, a_i^1, ..., a_i^heads]`` of ``self_channels + heads * channels`` features, no activation
(the network that stacks blocks chooses it). Attention that is one-hot on the self loop makes the
block two linear maps of ``x_i``.
"""

from __future__ import annotations

import torch
from torch import nn
from torch_geometric.nn import GATConv

from loosefit.errors import InputError
from loosefit.models.layers.init import undrawn


class GATBlock(nn.Module):
    """``x (N, in_channels)``, ``edge_index (2, E)`` int64 -> ``(N, self_channels + heads * channels)``.

    Args:
        in_channels: node features in.
        self_channels: features of the self-reinforced (linear) stream.
        channels: features per attention head of the aggregation stream.
        heads: attention heads (FitGar Sec. 5.1: 4).

    ``edge_index`` lists directed edges ``source -> target`` (both directions for a mesh); self loops
    are added by the attention layer. Nodes of several graphs batched as one disjoint graph never mix.

    Shapes:
        x ``(N, in_channels)``, edge_index ``(2, E)`` int64 -> ``(N, self_channels + heads * channels)``.
    """

    def __init__(self, in_channels: int, self_channels: int, channels: int, heads: int = 4):
        super().__init__()
        if min(in_channels, self_channels, channels, heads) < 1:
            raise InputError(f"GAT block sizes must be >= 1, got in {in_channels}, self {self_channels}, "
                             f"channels {channels}, heads {heads}")
        self.self_stream = undrawn(nn.Linear, in_channels, self_channels)
        self.attention = undrawn(GATConv, in_channels, channels, heads=heads, concat=True, add_self_loops=True)
        self.in_channels, self.self_channels, self.channels, self.heads = in_channels, self_channels, channels, heads
        self.out_channels = self_channels + heads * channels
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """torch's default initialisation of the self stream, then PyG's of the attention layer (Glorot
        projection and attention vectors, zero bias)."""
        self.self_stream.reset_parameters()
        # GATConv draws its projection twice when built (in its Linear's constructor and in its own
        # reset_parameters); drawn twice here too, the initial weights stay those of a plainly built GATConv
        self.attention.lin.reset_parameters()
        self.attention.reset_parameters()

    def extra_repr(self) -> str:
        return f"{self.in_channels}, self_channels={self.self_channels}, channels={self.channels}, heads={self.heads}"

    @classmethod
    def of_width(cls, in_channels: int, width: int, heads: int = 4, self_fraction: float = 0.5) -> "GATBlock":
        """A block of ``width`` output features: ``self_fraction`` of them in the self stream, the rest
        split evenly among the heads (FitGar Sec. 5.1's first coarse block: width 256 = 128 + 4 x 32)."""
        self_channels = int(round(width * self_fraction))
        rest = width - self_channels
        if self_channels < 1 or rest < heads or rest % heads:
            raise InputError(f"a GAT block of width {width} cannot split into a self stream of {self_channels} "
                             f"and {heads} equal heads")
        return cls(in_channels, self_channels, rest // heads, heads)

    def forward(self, x: torch.Tensor, edge_index: torch.Tensor) -> torch.Tensor:
        return torch.cat([self.self_stream(x), self.attention(x, edge_index)], dim=-1)
