"""The gradient of each shared loss term alone (:mod:`loosefit.train.losses`): it matches central finite
differences in float64 (``torch.autograd.gradcheck``), it reaches the prediction only (never the target, the
body or a masked frame), and the validation errors pool the squared distances of every counted frame."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.train.losses import (
    collision_loss,
    laplacian_difference,
    laplacian_operator,
    masked_errors_mm,
    normal_loss,
    vertex_distance,
    vertex_l1,
)

#: Two triangles sharing the edge (1, 2), and a third on the edge (2, 3): vertex 2 has three neighbours.
FACES = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4]])
REST = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.1], [0.3, 2.0, 0.0]])


def window(seed: int, B: int = 2, T: int = 3) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``pred``, ``target`` ``(B, T, 5, 3)`` float64 near the rest strip, every frame different, and a mask
    ``(B, T)`` with the first frame of the first window masked out (a burn-in)."""
    rng = np.random.default_rng(seed)
    target = torch.from_numpy(REST + rng.normal(0, 0.05, (B, T, 5, 3)))
    pred = (target + torch.from_numpy(rng.normal(0, 0.03, (B, T, 5, 3)))).requires_grad_(True)
    mask = torch.ones(B, T, dtype=torch.float64)
    mask[0, 0] = 0
    return pred, target, mask


def laplacian() -> torch.Tensor:
    return laplacian_operator(FACES, 5).double()


TERMS = {
    "vertex_distance": lambda p, t, m: vertex_distance(p, t, m),
    "vertex_l1": lambda p, t, m: vertex_l1(p, t, m),
    "laplacian": lambda p, t, m: laplacian_difference(p, t, laplacian(), m),
    "normal": lambda p, t, m: normal_loss(p, t, torch.from_numpy(FACES), m),
}


@pytest.mark.parametrize("name", list(TERMS))
def test_each_term_has_the_finite_difference_gradient_and_none_on_masked_frames(name):
    pred, target, mask = window(0)
    term = TERMS[name]
    assert torch.autograd.gradcheck(lambda p: term(p, target, mask), (pred,), eps=1e-6, atol=1e-7, rtol=1e-5)
    (grad,) = torch.autograd.grad(term(pred, target, mask), pred)
    assert grad[0, 0].abs().max() == 0  # the burn-in frame is not trained
    assert (grad[mask.bool()].abs().sum((-1, -2)) > 1e-6).all()  # every counted frame is
    target.requires_grad_(True)
    value = term(pred, target, mask)
    assert value.requires_grad and value.grad_fn is not None


def test_laplacian_gradient_is_the_transposed_laplacian_of_the_unit_differences():
    """``d/dp mean_v |L p_v - L t_v|`` on one frame is ``L^T u / V`` with ``u_v`` the unit vector of
    ``L (p - t)`` at ``v``: the term moves a vertex through its neighbours, not only itself."""
    pred, target, _ = window(1, B=1, T=1)
    L = laplacian().to_dense()
    (grad,) = torch.autograd.grad(laplacian_difference(pred, target, laplacian()), pred)
    d = L @ (pred - target)[0, 0].detach()
    u = d / d.norm(dim=-1, keepdim=True)
    torch.testing.assert_close(grad[0, 0], L.T @ u / 5, rtol=1e-10, atol=1e-12)


def test_collision_gradient_pushes_only_the_penetrating_vertices_along_the_body_normal():
    """``max(margin - n . (v - b), 0)`` averaged over vertices: a vertex deeper than the margin gets
    ``-n / V`` (per counted frame), one outside gets nothing, and the body is never moved."""
    B, T, V = 1, 2, 4
    body = torch.zeros(B, T, 2, 3, dtype=torch.float64, requires_grad=True)
    normals = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand(B, T, 2, 3).contiguous()
    nearest = torch.zeros(B, T, V, dtype=torch.int64)
    heights = torch.tensor([[-0.02, 0.003, 0.05, -0.001], [0.01, -0.03, 0.002, 0.2]], dtype=torch.float64)
    pred = torch.zeros(B, T, V, 3, dtype=torch.float64)
    pred[..., 2] = heights
    pred.requires_grad_(True)
    margin = 0.005
    assert torch.autograd.gradcheck(lambda p: collision_loss(p, body.detach(), normals, nearest, margin),
                                    (pred,), eps=1e-7, atol=1e-7)
    loss = collision_loss(pred, body, normals, nearest, margin)
    expected = float(torch.relu(margin - heights).mean())
    assert float(loss.detach()) == pytest.approx(expected, abs=1e-15)
    grad_pred, grad_body = torch.autograd.grad(loss, (pred, body))
    inside = (heights < margin).double()
    want = torch.zeros_like(pred)
    want[..., 2] = -inside / (T * V)
    torch.testing.assert_close(grad_pred, want, rtol=0, atol=1e-15)
    # the body is the same in every frame, so it receives the opposite push of the vertices that pierce it
    torch.testing.assert_close(grad_body.sum((0, 1, 2)), -grad_pred.sum((0, 1, 2)), rtol=0, atol=1e-15)


def test_validation_rmse_pools_squares_of_the_counted_frames_not_per_frame_rms():
    """Frames with different errors: ``rmse_mm`` is ``sqrt`` of the mean squared distance over every counted
    vertex and frame (not the mean of the frames' RMS values), ``mean_vertex_error_mm`` the mean distance."""
    rng = np.random.default_rng(3)
    target = rng.normal(0, 0.1, (2, 4, 6, 3))
    pred = target + rng.normal(0, 1, (2, 4, 1, 1)) * rng.normal(0, 0.01, (2, 4, 6, 3))  # frames scaled apart
    mask = np.ones((2, 4))
    mask[0, :2] = 0
    mask[1, 3] = 0
    d = np.linalg.norm(pred - target, axis=-1)  # (B, T, V)
    counted = d[mask.astype(bool)]  # (frames, V)
    pooled = 1e3 * np.sqrt((counted**2).mean())
    per_frame = 1e3 * np.sqrt((counted**2).mean(-1)).mean()
    assert abs(pooled - per_frame) > 0.05 * pooled  # the data tell the two apart
    got = masked_errors_mm(torch.from_numpy(pred), torch.from_numpy(target), torch.from_numpy(mask))
    assert got["rmse_mm"] == pytest.approx(pooled, rel=1e-9)
    assert got["mean_vertex_error_mm"] == pytest.approx(1e3 * counted.mean(), rel=1e-9)
    every = masked_errors_mm(torch.from_numpy(pred), torch.from_numpy(target))
    assert every["rmse_mm"] == pytest.approx(1e3 * np.sqrt((d**2).mean()), rel=1e-9)
    assert every["mean_vertex_error_mm"] == pytest.approx(1e3 * d.mean(), rel=1e-9)
