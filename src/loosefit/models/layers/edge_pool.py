"""Edge-contraction pooling and its unpooling (Diehl 2019, "Edge Contraction Pooling for Graph Neural
Networks"; FitGar's [Die19]), the operation of PyG's ``EdgePooling``.

Pooling ``x (N, C)`` over directed edges ``edge_index (2, E)``:

1. every edge ``(i -> j)`` gets a raw score ``w . [x_i, x_j] + b``, a softmax over the edges entering
   ``j``, plus 0.5 (``add_to_edge_score``, so that no score is near 0 and unpooling stays stable);
2. edges are visited by decreasing score and contracted when neither end is taken yet: about every
   second node disappears on a mesh (a greedy matching); nodes left over form clusters of one with
   score 1;
3. a cluster's feature is the sum of its nodes' features times its edge's score (the score carries the
   gradient to ``w`` and ``b``); the new edges join clusters whose nodes were joined, without
   duplicates (a contracted edge becomes a self loop, as in PyG).

Unpooling divides a cluster's feature by its score and copies it to each of its nodes, so
``unpool(pool(x))_i = sum of x over the cluster of i``: exact for a node left alone, the sum of both
ends for a contracted edge.

Same numbers as ``torch_geometric.nn.EdgePooling`` (tested), with the greedy contraction run on Python
integers instead of tensor elements: a 4k-vertex triangulated grid pools in 17 ms instead of 99 ms
(one CPU thread).

:meth:`EdgeContractionPooling.forward_static` pools with every shape fixed by the input graph, for a frame
captured in a CUDA graph: the greedy matching by rounds of locally best edges (:func:`greedy_contraction_rounds`;
an edge taken when no free edge beside it comes earlier in the greedy order: the same matching, Blelloch, Fineman
and Shun 2012), the pooled graph on ``N`` rows (the clusters first, then empty rows) as a padded neighbour table.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn
from torch_geometric.utils import coalesce, scatter, softmax

from loosefit.models.layers.init import undrawn

#: Added to every softmax edge score (PyG's default ``add_to_edge_score``).
SCORE_OFFSET = 0.5


class PoolInfo(NamedTuple):
    """What unpooling needs: ``cluster (N,)`` int64 cluster of each input node, ``score (N',)`` each
    cluster's score, and the input graph ``edge_index (2, E)`` and ``batch (N,)``."""

    cluster: torch.Tensor
    score: torch.Tensor
    edge_index: torch.Tensor
    batch: torch.Tensor


def greedy_contraction(edge_index: torch.Tensor, score: torch.Tensor, num_nodes: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Clusters of a greedy edge matching by decreasing ``score (E,)``.

    Returns ``cluster (N,)`` int64 (contracted edges first, in the order they were taken, then the
    nodes left alone in index order) and ``taken (K,)`` int64, the indices of the contracted edges.
    """
    order = torch.argsort(score, descending=True).tolist()
    src, dst = edge_index.cpu().tolist()
    free = [True] * num_nodes
    cluster = [0] * num_nodes
    taken = []
    for e in order:
        i, j = src[e], dst[e]
        if not free[i] or not free[j]:
            continue
        cluster[i] = cluster[j] = len(taken)
        free[i] = free[j] = False
        taken.append(e)
    k = len(taken)
    for n in range(num_nodes):
        if free[n]:
            cluster[n] = k
            k += 1
    device = edge_index.device
    return torch.tensor(cluster, dtype=torch.long, device=device), torch.tensor(taken, dtype=torch.long, device=device)


def greedy_contraction_rounds(edge_index: torch.Tensor, score: torch.Tensor, num_nodes: int,
                              rounds: int | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """:func:`greedy_contraction`'s matching in parallel rounds, without host synchronisation when ``rounds`` is
    given: each round takes every edge whose two ends are free and that comes first in the greedy order (by
    decreasing ``score``, ties as :func:`torch.argsort` orders them) among the free edges at both its ends.

    Returns ``cluster (N,)`` int64 (as :func:`greedy_contraction`: contracted edges in greedy order, then the
    nodes left alone in index order), ``taken (E,)`` bool and ``done ()`` bool: whether the rounds finished the
    matching (``rounds=None`` runs until they do, checking on the host after each round)."""
    src, dst = edge_index[0], edge_index[1]
    E = src.shape[0]
    order = torch.argsort(score, descending=True)
    rank = torch.empty_like(order).scatter_(0, order, torch.arange(E, device=order.device))
    free = torch.ones(num_nodes, dtype=torch.bool, device=src.device)
    taken = torch.zeros(E, dtype=torch.bool, device=src.device)
    never = torch.full((num_nodes,), E, dtype=rank.dtype, device=rank.device)
    k = 0
    while rounds is None or k < rounds:
        alive = free[src] & free[dst]
        if rounds is None and not bool(alive.any()):
            break
        key = torch.where(alive, rank, E)
        best = never.scatter_reduce(0, src, key, "amin").scatter_reduce_(0, dst, key, "amin")
        win = alive & (best[src] == rank) & (best[dst] == rank)
        taken |= win
        hit = torch.zeros(num_nodes, dtype=torch.long, device=src.device)
        hit = hit.index_add_(0, src, win.long()).index_add_(0, dst, win.long())
        free &= hit == 0
        k += 1
    done = ~(free[src] & free[dst]).any()
    in_order = taken[order].long()
    edge_cluster = torch.empty_like(order).scatter_(0, order, in_order.cumsum(0) - 1)
    contracted = in_order.sum()
    cluster = torch.full((num_nodes,), -1, dtype=torch.long, device=src.device)
    own = torch.where(taken, edge_cluster, -1)
    cluster = cluster.scatter_reduce(0, src, own, "amax").scatter_reduce_(0, dst, own, "amax")
    alone = cluster < 0
    cluster = torch.where(alone, contracted + alone.long().cumsum(0) - 1, cluster)
    return cluster, taken, done


def pooled_table(cluster: torch.Tensor, edge_index: torch.Tensor, num_nodes: int,
                 width: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The pooled graph as :func:`~loosefit.models.layers.gat_block.incoming_table` lays out :meth:`forward`'s
    pooled edges, on ``num_nodes`` rows (clusters past the last hold no node): every other cluster an edge joins to
    a cluster, once, in increasing order, then the cluster itself. Returns ``table, valid (N, width)`` and
    ``fits ()`` bool (False when a cluster has more neighbours than the width holds: the table is then cut
    short)."""
    N, device = num_nodes, cluster.device
    cs, cd = cluster[edge_index[0]], cluster[edge_index[1]]
    key = torch.where(cs != cd, cd * N + cs, N * N)  # contracted edges (self loops) last, dropped
    key = torch.sort(key).values
    first = torch.ones_like(key, dtype=torch.bool)
    first[1:] = key[1:] != key[:-1]
    keep = first & (key < N * N)
    dst, src = torch.div(key, N, rounding_mode="floor").clamp_max(N - 1), key % N
    count = torch.zeros(N, dtype=torch.long, device=device).index_add_(0, dst, keep.long())
    start = count.cumsum(0) - count
    slot = keep.long().cumsum(0) - 1 - start[dst]
    fits = (count < width).all()
    place = torch.where(keep & (slot < width - 1), dst * width + slot, N * width)  # the rest to a spare cell
    table = torch.arange(N, device=device).repeat_interleave(width)
    table = torch.cat([table, table.new_zeros(1)]).scatter_(0, place, src)[:-1].view(N, width)
    valid = torch.zeros(N * width + 1, dtype=torch.bool, device=device).scatter_(0, place, keep)[:-1]
    nodes = torch.arange(N, device=device)
    # the cluster itself, last (the table holds it there); index_fill_ takes the value as a kernel argument, where
    # ``valid[...] = True`` copies a host scalar to the device, which a CUDA graph capture refuses
    valid.index_fill_(0, nodes * width + count.clamp_max(width - 1), True)
    return table, valid.view(N, width), fits


class EdgeContractionPooling(nn.Module):
    """Learned edge-contraction pooling of ``channels`` node features (see the module docstring).

    ``forward(x (N, C), edge_index (2, E), batch (N,))`` -> ``(x (N', C), edge_index (2, E'), batch (N',),
    info)``; ``unpool(x (N', C'), info)`` -> ``(N, C')``. Graphs batched as one disjoint graph are pooled
    each on its own (no edge joins them).

    Shapes:
        x ``(N, channels)``, edge_index ``(2, E)`` int64, batch ``(N,)`` int64 -> x ``(N', channels)``,
        edge_index ``(2, E')``, batch ``(N',)``, :class:`PoolInfo`; unpool: ``(N', C)`` -> ``(N, C)``.
    """

    def __init__(self, channels: int):
        super().__init__()
        self.channels = channels
        self.lin = undrawn(nn.Linear, 2 * channels, 1)
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """torch's default initialisation of the edge score's linear layer."""
        self.lin.reset_parameters()

    def extra_repr(self) -> str:
        return f"{self.channels}"

    def forward(self, x: torch.Tensor, edge_index: torch.Tensor, batch: torch.Tensor):
        raw = self.lin(torch.cat([x[edge_index[0]], x[edge_index[1]]], dim=-1)).view(-1)
        score = softmax(raw, edge_index[1], num_nodes=x.shape[0]) + SCORE_OFFSET
        cluster, taken = greedy_contraction(edge_index, score.detach(), x.shape[0])
        clusters = int(cluster.max()) + 1 if len(cluster) else 0
        pooled = scatter(x, cluster, dim=0, dim_size=clusters, reduce="sum")
        cluster_score = torch.cat([score[taken], x.new_ones(clusters - len(taken))])
        new_edges = coalesce(cluster[edge_index], num_nodes=clusters)
        new_batch = batch.new_empty(clusters).scatter_(0, cluster, batch)
        return pooled * cluster_score[:, None], new_edges, new_batch, PoolInfo(cluster, cluster_score, edge_index, batch)

    def forward_static(self, x: torch.Tensor, edge_index: torch.Tensor, width: int, rounds: int | None = None):
        """:meth:`forward` with every shape fixed by the input (one graph, or several as one): ``x (N, C)``,
        ``edge_index (2, E)`` -> pooled ``x (N, C)`` (cluster ``c`` on row ``c``; rows past the last cluster zero),
        the pooled graph's ``table, valid (N, width)`` (:func:`pooled_table`), ``info`` for :meth:`unpool` (its
        ``edge_index`` and ``batch`` left None) and ``exact ()`` bool: whether the matching finished within
        ``rounds`` and every cluster's neighbours fit in ``width`` (otherwise the outputs are not
        :meth:`forward`'s)."""
        N = x.shape[0]
        raw = self.lin(torch.cat([x[edge_index[0]], x[edge_index[1]]], dim=-1)).view(-1)
        score = softmax(raw, edge_index[1], num_nodes=N) + SCORE_OFFSET
        cluster, taken, done = greedy_contraction_rounds(edge_index, score.detach(), N, rounds)
        pooled = x.new_zeros(N, x.shape[1]).index_add_(0, cluster, x)
        own = torch.where(taken, cluster[edge_index[0]], N)  # a contracted edge's cluster; the rest to a spare row
        cluster_score = x.new_ones(N + 1).scatter(0, own, score)[:N]
        table, valid, fits = pooled_table(cluster, edge_index, N, width)
        return pooled * cluster_score[:, None], table, valid, PoolInfo(cluster, cluster_score, None, None), done & fits

    @staticmethod
    def unpool(x: torch.Tensor, info: PoolInfo) -> torch.Tensor:
        """Pooled features ``(N', C)`` back on the input nodes ``(N, C)``: each cluster's feature divided
        by its score, copied to its nodes."""
        return (x / info.score[:, None])[info.cluster]
