"""Loss terms against hand-computed values."""

import numpy as np
import pytest
import torch

from loosefit.train import losses


def test_vertex_terms_and_mask():
    pred = torch.zeros(2, 3, 4, 3)
    target = torch.zeros(2, 3, 4, 3)
    target[..., 0] = 0.03
    target[..., 1] = 0.04  # every vertex 5 cm off
    target[:, 0] = 10.0  # frame 0 wildly off, but masked out below
    mask = losses.frame_mask(torch.tensor([1, 1]), 3)
    assert torch.allclose(losses.vertex_distance(pred, target, mask), torch.tensor(0.05))
    assert torch.allclose(losses.vertex_l1(pred, target, mask), torch.tensor(0.07 / 3))
    assert mask.tolist() == [[0, 1, 1], [0, 1, 1]]


def test_laplacian_of_a_translation_is_unchanged():
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]])
    verts = torch.tensor([[0, 0, 0.1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], dtype=torch.float32)[None, None]
    L = losses.laplacian_operator(faces, 5)
    lap = losses.apply_laplacian(L, verts)
    # Centre vertex: sum over its four neighbours of (x_j - x_i).
    assert torch.allclose(lap[0, 0, 0], torch.tensor([0.0, 0.0, -0.4]), atol=1e-6)
    assert losses.laplacian_difference(verts + 0.3, verts, L) < 1e-6


def test_normal_and_collision_terms():
    faces = torch.tensor([[0, 1, 2]])
    tri = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])[None, None]
    flipped = tri[..., [0, 2, 1], :]
    assert torch.allclose(losses.normal_loss(tri, tri, faces), torch.tensor(0.0), atol=1e-7)
    assert torch.allclose(losses.normal_loss(tri[..., [0, 1, 2], :], flipped[..., [0, 1, 2], :], faces), torch.tensor(2.0))
    body = torch.zeros(1, 1, 1, 3)
    normals = torch.tensor([0.0, 0.0, 1.0]).expand(1, 1, 1, 3)
    pred = torch.tensor([[0.0, 0, 0.01], [0, 0, -0.02]])[None, None]  # one outside, one 2 cm inside
    nearest = torch.zeros(1, 1, 2, dtype=torch.long)
    assert torch.allclose(losses.collision_loss(pred, body, normals, nearest), torch.tensor(0.01))
    assert torch.allclose(losses.collision_loss(pred, body, normals, nearest, margin=0.005), torch.tensor(0.0125))


def test_masked_validation_errors_against_numpy():
    """``rmse_mm`` pools the squared vertex distances of the counted frames; ``mean_vertex_error_mm`` the distances."""
    from loosefit.train.losses import masked_errors_mm

    gen = torch.Generator().manual_seed(0)
    pred, target = torch.randn(2, 5, 7, 3, generator=gen), torch.randn(2, 5, 7, 3, generator=gen)
    mask = torch.ones(2, 5)
    mask[0, :2] = 0  # a burn-in of two frames in the first window
    d = np.linalg.norm((pred - target).numpy().astype(np.float64), axis=-1)  # (2, 5, 7)
    counted = np.concatenate([d[0, 2:], d[1]])  # (8, 7)
    got = masked_errors_mm(pred, target, mask)
    assert got["rmse_mm"] == pytest.approx(np.sqrt((counted**2).mean()) * 1e3, rel=1e-5)
    assert got["mean_vertex_error_mm"] == pytest.approx(counted.mean() * 1e3, rel=1e-5)
    everything = masked_errors_mm(pred, target)
    assert everything["rmse_mm"] == pytest.approx(np.sqrt((d**2).mean()) * 1e3, rel=1e-5)
    assert everything["mean_vertex_error_mm"] == pytest.approx(d.mean() * 1e3, rel=1e-5)
    one = masked_errors_mm(pred[0, 0], target[0, 0])  # one frame (V, 3)
    assert one["mean_vertex_error_mm"] == pytest.approx(d[0, 0].mean() * 1e3, rel=1e-5)
