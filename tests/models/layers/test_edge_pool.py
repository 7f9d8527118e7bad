"""Edge-contraction pooling (FitGar's [Die19]) against PyG's EdgePooling, on a garment mesh graph."""

import numpy as np
import pytest
import torch
from torch_geometric.nn import EdgePooling

from loosefit.models.layers.edge_pool import EdgeContractionPooling, greedy_contraction


def grid_edges(nx, ny):
    idx = np.arange(nx * ny).reshape(ny, nx)
    pairs = np.concatenate([np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
                            np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1),
                            np.stack([idx[:-1, :-1].ravel(), idx[1:, 1:].ravel()], 1)])  # triangulated grid
    both = np.concatenate([pairs, pairs[:, ::-1]]).T
    return torch.from_numpy(np.ascontiguousarray(both)).long()


@pytest.fixture
def graph():
    torch.manual_seed(0)
    edges = grid_edges(12, 10)
    return torch.randn(120, 6), edges, torch.zeros(120, dtype=torch.long)


def test_same_numbers_as_pyg(graph):
    x, edges, batch = graph
    ours = EdgeContractionPooling(6)
    ref = EdgePooling(6)
    ref.lin.load_state_dict(ours.lin.state_dict())
    a = ours(x, edges, batch)
    b = ref(x, edges, batch)
    torch.testing.assert_close(a[0], b[0])
    assert torch.equal(a[1], b[1]) and torch.equal(a[2], b[2])
    assert torch.equal(a[3].cluster, b[3].cluster)
    y = torch.randn(a[0].shape[0], 4)
    torch.testing.assert_close(ours.unpool(y, a[3]), ref.unpool(y, b[3])[0])


def test_pooling_about_halves_and_unpooling_restores(graph):
    x, edges, batch = graph
    pool = EdgeContractionPooling(6)
    pooled, new_edges, new_batch, info = pool(x, edges, batch)
    n = pooled.shape[0]
    # a greedy matching of a triangulated grid contracts most vertices in pairs
    assert 60 <= n <= 75, n
    assert new_edges.max() < n and len(new_batch) == n
    assert pool.unpool(pooled, info).shape == x.shape


def test_round_trip_is_the_cluster_sum(graph):
    """unpool(pool(x)) gives every node the sum of its cluster: a constant c comes back exactly as c on
    nodes left alone and 2c on both ends of a contracted edge; any signal likewise."""
    x, edges, batch = graph
    pool = EdgeContractionPooling(6)
    c = torch.full((120, 6), 0.7)
    pooled, _, _, info = pool(c, edges, batch)
    size = torch.bincount(info.cluster)[info.cluster].float()
    assert set(size.tolist()) == {1.0, 2.0}
    torch.testing.assert_close(pool.unpool(pooled, info), 0.7 * size[:, None].expand(-1, 6))
    pooled, _, _, info = pool(x, edges, batch)
    sums = torch.zeros(pooled.shape[0], 6).index_add_(0, info.cluster, x)[info.cluster]
    torch.testing.assert_close(pool.unpool(pooled, info), sums)


def test_batched_graphs_pool_separately():
    torch.manual_seed(1)
    e = grid_edges(6, 5)
    edges = torch.cat([e, e + 30], 1)
    batch = torch.cat([torch.zeros(30), torch.ones(30)]).long()
    pool = EdgeContractionPooling(3)
    _, _, new_batch, info = pool(torch.randn(60, 3), edges, batch)
    # no cluster spans both graphs
    for k in range(int(info.cluster.max()) + 1):
        assert len(set(batch[info.cluster == k].tolist())) == 1
    assert set(new_batch.tolist()) == {0, 1}


def test_greedy_contraction_order():
    # a path 0-1-2-3: the best edge (1,2) first, then nothing else fits
    edges = torch.tensor([[0, 1, 2], [1, 2, 3]])
    cluster, taken = greedy_contraction(edges, torch.tensor([0.1, 0.9, 0.2]), 4)
    assert taken.tolist() == [1]
    assert cluster.tolist() == [1, 0, 0, 2]


def test_gradient_reaches_the_score():
    torch.manual_seed(2)
    e = grid_edges(5, 5)
    pool = EdgeContractionPooling(4)
    x = torch.randn(25, 4)
    pooled, _, _, info = pool(x, e, torch.zeros(25, dtype=torch.long))
    (pooled ** 2).sum().backward()
    assert pool.lin.weight.grad.abs().sum() > 0
