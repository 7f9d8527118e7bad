"""EdgeConv (Wang et al. 2019, "Dynamic Graph CNN") over a fixed graph, as a dense neighbour gather.

For each vertex ``i`` with neighbours ``N(i)``::

    x'_i = max_{j in N(i)} act(W [x_i, x_j - x_i] + b)

with a single linear layer and a LeakyReLU as the edge function. Splitting ``W = [W_a | W_b]``
gives ``W [x_i, x_j - x_i] = (W_a - W_b) x_i + W_b x_j``, and a monotone activation commutes with
the max, so::

    x'_i = act((W_a - W_b) x_i + b + max_{j in N(i)} W_b x_j)

which is exactly the same function but projects each vertex once and takes a channel-wise max over
a padded neighbour table (:func:`neighbour_table`) instead of materialising one message per edge.
The forward pass scatters nothing (PyG's message passing does, non-deterministically on GPUs); the
backward pass scatters one value per vertex and channel.
Equal to ``torch_geometric.nn.EdgeConv(Sequential(Linear(2C, C'), LeakyReLU), aggr="max")`` on the
same (symmetric) graph; a vertex without neighbours here sees itself (there it would get zeros).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from loosefit.geometry.laplacian import edges
from loosefit.models.layers.init import undrawn
from loosefit.models.layers.mlp import NEGATIVE_SLOPE


def neighbour_table(faces: np.ndarray, num_verts: int) -> np.ndarray:
    """``(V, D)`` int64 mesh-edge neighbours of each vertex, ``D`` the largest degree. Rows of
    lower-degree vertices are padded with their first neighbour (a repeat does not change a max);
    a vertex on no edge lists itself."""
    e = edges(np.asarray(faces, np.int64))
    both = np.concatenate([e, e[:, ::-1]])
    both = both[np.lexsort((both[:, 1], both[:, 0]))]
    degree = np.bincount(both[:, 0], minlength=num_verts)
    width = max(int(degree.max(initial=0)), 1)
    table = np.repeat(np.arange(num_verts, dtype=np.int64)[:, None], width, 1)
    start = np.concatenate([[0], np.cumsum(degree)[:-1]])
    has = degree > 0
    for slot in range(width):
        # slot k of vertex i: its k-th neighbour, or its first one when it has fewer
        pick = start + np.where(slot < degree, slot, 0)
        table[has, slot] = both[pick[has], 1]
    return table


class EdgeConv(nn.Module):
    """One EdgeConv layer over a neighbour table (see the module docstring).

    Shapes:
        x ``(..., V, in_channels)``, neighbours ``(V, D)`` int64 (:func:`neighbour_table`) ->
        ``(..., V, out_channels)``.
    """

    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        self.linear = undrawn(nn.Linear, 2 * in_channels, out_channels)  # acts on [x_i, x_j - x_i]
        self.in_channels, self.out_channels = in_channels, out_channels
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """torch's default initialisation of the edge function's linear layer."""
        self.linear.reset_parameters()

    def extra_repr(self) -> str:
        return f"{self.in_channels}, {self.out_channels}"

    def forward(self, x: torch.Tensor, neighbours: torch.Tensor) -> torch.Tensor:
        C = self.in_channels
        w_centre, w_edge = self.linear.weight[:, :C], self.linear.weight[:, C:]
        own = x @ (w_centre - w_edge).T + self.linear.bias  # (..., V, out)
        other = x @ w_edge.T  # (..., V, out)
        return nn.functional.leaky_relu(own + neighbour_max(other, neighbours), NEGATIVE_SLOPE)


#: Elements of the ``(frames, D, V, C)`` neighbour gather held at once; more frames are done in chunks.
#: 16 MB of float32: a training step on 512 frames of a 3.7k-vertex dress took 7.9 s with 128 MB
#: chunks, 6.6-6.8 s with 4 or 16 MB ones (1 thread).
GATHER_BUDGET = 2**22


def neighbour_max(x: torch.Tensor, neighbours: torch.Tensor) -> torch.Tensor:
    """Channel-wise max over each vertex's neighbours: ``x (..., V, C)``, ``neighbours (V, D)`` -> ``(..., V, C)``.

    Under autograd the winning neighbour of every vertex and channel is found first, then its value
    is gathered: the gradient flows to the winners only (as through ``amax`` without ties) and
    backward scatters ``(..., V, C)`` values instead of ``(..., V, D, C)``. Leading axes are
    processed in chunks of at most :data:`GATHER_BUDGET` gathered elements.
    """
    V, C = x.shape[-2:]
    flat = x.reshape(-1, V, C)
    order = neighbours.T.reshape(-1)
    step = max(1, GATHER_BUDGET // max(order.numel() * C, 1))

    def gathered(chunk):  # (n, D, V, C): index_select beats advanced indexing on the CPU
        return chunk.index_select(-2, order).unflatten(-2, neighbours.T.shape)

    if not (torch.is_grad_enabled() and x.requires_grad):
        return torch.cat([gathered(c).amax(1) for c in flat.split(step)]).reshape(x.shape)
    with torch.no_grad():
        slot = torch.cat([gathered(c).max(1).indices for c in flat.split(step)])  # (n, V, C) in [0, D)
        source = torch.gather(neighbours.expand(len(slot), *neighbours.shape), -1, slot)
    return torch.gather(flat, -2, source).reshape(x.shape)
