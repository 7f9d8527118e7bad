"""EdgeConv over a neighbour table against PyTorch Geometric's EdgeConv on the same mesh graph."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from loosefit.models.layers.edge_conv import EdgeConv, neighbour_table
from loosefit.models.layers.mlp import NEGATIVE_SLOPE


def grid_faces(n: int) -> np.ndarray:
    """Triangles ``(2 (n-1)^2, 3)`` of an ``n x n`` vertex grid (vertex degrees 2 to 6)."""
    ij = np.arange(n * n).reshape(n, n)
    a, b, c, d = ij[:-1, :-1].ravel(), ij[:-1, 1:].ravel(), ij[1:, :-1].ravel(), ij[1:, 1:].ravel()
    return np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def test_neighbour_table_lists_each_vertex_neighbours_padded_with_the_first():
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    table = neighbour_table(faces, 5)  # vertex 4 is on no edge
    assert table.tolist() == [[1, 2, 1], [0, 2, 3], [0, 1, 3], [1, 2, 1], [4, 4, 4]]


def test_edge_conv_equals_torch_geometric():
    from torch_geometric.nn import EdgeConv as PygEdgeConv

    torch.manual_seed(0)
    faces, V = grid_faces(6), 36
    ours = EdgeConv(4, 5)
    theirs = PygEdgeConv(nn.Sequential(nn.Linear(8, 5), nn.LeakyReLU(NEGATIVE_SLOPE)), aggr="max")
    theirs.nn[0].load_state_dict(ours.linear.state_dict())
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.concatenate([e, e[:, ::-1]]), axis=0)
    edge_index = torch.from_numpy(e[:, ::-1].T.copy())  # row 0 sources j, row 1 targets i

    x = torch.randn(3, V, 4, requires_grad=True)
    table = torch.from_numpy(neighbour_table(faces, V))
    out = ours(x, table)
    ref = torch.stack([theirs(x[b], edge_index) for b in range(3)])
    assert out.shape == (3, V, 5)
    assert torch.allclose(out, ref, atol=1e-6)
    g_out, = torch.autograd.grad((out * torch.linspace(-1, 1, 5)).sum(), x)
    g_ref, = torch.autograd.grad((ref * torch.linspace(-1, 1, 5)).sum(), x)
    assert torch.allclose(g_out, g_ref, atol=1e-5)


def test_chunked_neighbour_max_equals_one_pass(monkeypatch):
    from loosefit.models.layers import edge_conv

    torch.manual_seed(1)
    faces, V = grid_faces(5), 25
    table = torch.from_numpy(neighbour_table(faces, V))
    x = torch.randn(2, 3, V, 4, requires_grad=True)
    whole = edge_conv.neighbour_max(x, table)
    g_whole, = torch.autograd.grad(whole.sum(), x)
    monkeypatch.setattr(edge_conv, "GATHER_BUDGET", 1)  # one frame per chunk
    chunked = edge_conv.neighbour_max(x, table)
    g_chunked, = torch.autograd.grad(chunked.sum(), x)
    with torch.no_grad():
        plain = edge_conv.neighbour_max(x, table)
    reference = x[..., table, :].amax(-2)  # (2, 3, V, D, 4) -> max over the neighbours
    assert torch.equal(whole, reference) and torch.equal(chunked, reference) and torch.equal(plain, reference)
    assert torch.equal(g_whole, g_chunked)
