"""The gradient of each SwinGar loss term alone (SwinGar Eqs. 11-14) with respect to the predicted vertices,
on a strip of three triangles in float64: every term matches central finite differences
(``torch.autograd.gradcheck``) and pushes every frame, and has the closed-form gradient where one is short
(vertex, gravity, edge, collision)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.geometry.laplacian import edges
from loosefit.models.multi_garment import face_pairs
from loosefit.models.swingar import GRAVITY, SwinGar

from .test_swingar_signs import FLAT, STRIP, TINY

TERMS = ("vert", "edge", "bend", "gravity", "collision")


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return SwinGar({"num_joints": 3, "parents": [-1, 0, 1], "shape_values": 2}, TINY).double()


def batch(seed: int = 0, T: int = 2) -> tuple[torch.Tensor, dict]:
    """A prediction ``(1, T, 5, 3)`` and a batch whose simulated strip, body and masses differ per frame; the
    body lies 3 mm under some vertices (inside the collision margin) and far under others."""
    rng = np.random.default_rng(seed)
    target = torch.from_numpy(FLAT + rng.normal(0, 0.05, (1, T, 5, 3)))
    pred = (target + torch.from_numpy(rng.normal(0, 0.02, (1, T, 5, 3)))).requires_grad_(True)
    below = torch.tensor([0.001, 0.0005, 0.05, 0.0015, 0.1], dtype=torch.float64)  # heights of the body under pred
    body = (pred.detach() - torch.stack([torch.zeros(5), torch.zeros(5), below], -1)).requires_grad_(True)
    normals = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand(1, T, 5, 3).contiguous()
    g = {"faces": torch.from_numpy(STRIP), "edges": torch.from_numpy(edges(STRIP)),
         "face_pairs": torch.from_numpy(face_pairs(STRIP)),
         "mass": torch.tensor([0.01, 0.02, 0.03, 0.015, 0.005], dtype=torch.float64, requires_grad=True)}
    return pred, {"graph_tensors": g, "verts": target.requires_grad_(True), "body": body, "body_normals": normals,
                  "body_nearest": torch.arange(5).expand(1, T, 5)}


@pytest.mark.parametrize("term", TERMS)
def test_each_term_matches_finite_differences_and_reaches_only_the_prediction(model, term):
    pred, b = batch()
    b["verts"], b["body"], b["graph_tensors"]["mass"] = (x.detach() for x in (b["verts"], b["body"],
                                                                               b["graph_tensors"]["mass"]))
    assert torch.autograd.gradcheck(lambda p: model.loss_terms(p, b)[term], (pred,), eps=1e-7, atol=1e-6, rtol=1e-4)
    (grad,) = torch.autograd.grad(model.loss_terms(pred, b)[term], pred)
    assert (grad.abs().sum((0, 2, 3)) > 0).all()  # every frame is pushed


def test_closed_form_gradients(model):
    pred, b = batch(1)
    T, V = pred.shape[1:3]
    terms = model.loss_terms(pred, b)
    d = (pred - b["verts"]).detach()
    # vert: mean over frames and vertices of |p - x|^2 -> 2 (p - x) / (T V)
    (g,) = torch.autograd.grad(terms["vert"], pred, retain_graph=True)
    torch.testing.assert_close(g, 2 * d / (T * V), rtol=1e-12, atol=1e-15)
    # gravity: 9.8 sum_i m_i (p_iz - x_iz), mean over frames -> 9.8 m_i / T on z only
    (g,) = torch.autograd.grad(terms["gravity"], pred, retain_graph=True)
    want = torch.zeros_like(g)
    want[..., 2] = GRAVITY * b["graph_tensors"]["mass"].detach() / T
    torch.testing.assert_close(g, want, rtol=1e-12, atol=1e-15)
    # collision: vertices closer than eps to the body get 2 (h - eps) n / (T V), the others nothing
    (g,) = torch.autograd.grad(terms["collision"], pred, retain_graph=True)
    h = ((pred - b["body"]) * b["body_normals"]).sum(-1).detach()
    want = torch.zeros_like(g)
    want[..., 2] = 2 * torch.clamp(h - TINY.collision_eps, max=0.0) / (T * V)
    torch.testing.assert_close(g, want, rtol=1e-10, atol=1e-15)
    assert (want[..., 2] != 0).sum() == 3 * T  # three vertices of each frame within the margin
    # edge: per edge (l' - l)^2 averaged over frames and edges; d/dp_a = 2 (l' - l) u / (T E), -u at the other end
    e = b["graph_tensors"]["edges"]
    (g,) = torch.autograd.grad(terms["edge"], pred, retain_graph=True)
    vec = (pred[..., e[:, 0], :] - pred[..., e[:, 1], :]).detach()
    length = vec.norm(dim=-1, keepdim=True)
    rest = (b["verts"][..., e[:, 0], :] - b["verts"][..., e[:, 1], :]).detach().norm(dim=-1, keepdim=True)
    push = 2 * (length - rest) * vec / length / (T * len(e))
    want = torch.zeros_like(g).index_add_(2, e[:, 0], push).index_add_(2, e[:, 1], -push)
    torch.testing.assert_close(g, want, rtol=1e-10, atol=1e-15)


def test_bending_gradient_of_a_flat_strip_is_zero_and_a_fold_is_pushed_flat(model):
    """The bending term is 0 with a zero gradient on a flat strip; folded, its gradient (checked against finite
    differences above) lowers it along the negative gradient."""
    _, b = batch(T=1)
    b = {k: b[k] for k in ("graph_tensors", "verts")}  # no body: the bending term alone matters here
    flat = torch.from_numpy(FLAT)[None, None].clone().requires_grad_(True)
    (g,) = torch.autograd.grad(model.loss_terms(flat, b | {"verts": flat.detach()})["bend"], flat)
    assert g.abs().max() < 1e-12
    folded = flat.detach().clone()
    folded[..., 4, 2] = 0.5
    folded.requires_grad_(True)
    bend = model.loss_terms(folded, b | {"verts": flat.detach()})["bend"]
    (g,) = torch.autograd.grad(bend, folded)
    assert g.abs().max() > 0
    lower = model.loss_terms(folded.detach() - 1e-3 * g, b | {"verts": flat.detach()})["bend"]
    assert float(lower) < float(bend.detach())
