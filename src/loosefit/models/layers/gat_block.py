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

:meth:`GATBlock.forward_table` computes the same block over a padded table of each node's incoming edges
(:func:`incoming_table`, built once per graph) instead of the edge list: no self loops removed and added per
call, no scatter, every shape fixed by the table, so that a frame can be captured in a CUDA graph
(:mod:`loosefit.models.fitgar_stream`). The two agree to float round-off (the sums run in another order).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from torch_geometric.nn import GATConv

from loosefit.errors import InputError
from loosefit.models.layers.init import undrawn


def incoming_table(edge_index: np.ndarray, num_nodes: int, width: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each node's attention neighbourhood as :class:`GATConv` builds it from ``edge_index (2, E)`` (``source ->
    target``), in the order it sums them: the sources of the node's incoming edges in the order of
    ``edge_index`` (self loops left out, repeated edges kept), then the node itself (GATConv's added self loop).

    Returns ``table (N, D)`` int64 (padded with the node itself) and ``valid (N, D)`` bool, ``D = width`` or one
    more than the largest in-degree."""
    src, dst = np.asarray(edge_index, np.int64).reshape(2, -1)
    keep = src != dst
    src, dst = src[keep], dst[keep]
    order = np.argsort(dst, kind="stable")
    src, dst = src[order], dst[order]
    degree = np.bincount(dst, minlength=num_nodes)
    D = int(degree.max(initial=0)) + 1 if width is None else int(width)
    if degree.max(initial=0) + 1 > D:
        raise ValueError(f"a node has {degree.max()} incoming edges, more than a table of width {D} holds")
    start = np.concatenate([[0], np.cumsum(degree)[:-1]]).astype(np.int64)
    table = np.repeat(np.arange(num_nodes, dtype=np.int64)[:, None], D, 1)
    valid = np.zeros((num_nodes, D), bool)
    table[dst, np.arange(len(dst)) - start[dst]] = src
    valid[dst, np.arange(len(dst)) - start[dst]] = True
    valid[np.arange(num_nodes), degree] = True  # the self loop, last
    return table, valid


def gat_conv_table(conv: GATConv, x: torch.Tensor, table: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """``conv(x, edge_index)`` of a concatenating :class:`GATConv` (no edge features, no residual, no dropout at
    work) over the padded table of :func:`incoming_table`: ``x (N, in)`` -> ``(N, heads * out)``.

    The softmax's sum and the aggregation add the neighbours slot by slot in the table's order, as PyG's
    one-threaded CPU scatter adds the edges, each product rounded before its sum: on the CPU with one thread the
    result is GATConv's to the bit (the edge pooling after it then takes the same edges)."""
    H, C = conv.heads, conv.out_channels
    N, D = table.shape
    h = conv.lin(x).view(N, H, C)
    a_src, a_dst = (h * conv.att_src).sum(-1), (h * conv.att_dst).sum(-1)  # (N, H)
    s = a_src.index_select(0, table.reshape(-1)).view(N, D, H) + a_dst[:, None]
    s = nn.functional.leaky_relu(s, conv.negative_slope).masked_fill(~valid[:, :, None], float("-inf"))
    e = (s - s.amax(1, keepdim=True)).exp()  # (N, D, H), zero on padding
    total = e.new_zeros(N, H)
    for d in range(D):
        total = total + e[:, d]
    P = e / (total + 1e-16)[:, None]  # PyG's softmax, its guard against an empty sum included
    columns = table.T.contiguous()
    out = h.new_zeros(N, H, C)
    if torch.is_grad_enabled() and (x.requires_grad or h.requires_grad):
        for d in range(D):  # slot by slot: no (N, D, H, C) tensor is written
            out = out + P[:, d, :, None] * h.index_select(0, columns[d])
    else:  # the same sums into buffers allocated once (large temporaries cost page faults on every call)
        row, product = torch.empty_like(out), torch.empty_like(out)
        for d in range(D):
            torch.index_select(h, 0, columns[d], out=row)
            out.add_(torch.mul(P[:, d, :, None], row, out=product))
    out = out.view(N, H * C)
    return out if conv.bias is None else out + conv.bias


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

    def forward_table(self, x: torch.Tensor, table: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """:meth:`forward` over the padded table of :func:`incoming_table` (inference: attention dropout off)."""
        if self.attention.training and self.attention.dropout > 0:
            raise ValueError("GATBlock.forward_table runs without attention dropout: put the block in eval mode")
        return torch.cat([self.self_stream(x), gat_conv_table(self.attention, x, table, valid)], dim=-1)
