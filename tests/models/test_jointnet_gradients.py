"""Where the gradient of each JointNet loss term goes, on a tiny float64 model built from sizes alone (no
store): the sparsity term (JointNet Eq. 8) reaches the association only, with the closed-form gradient; the
cloth and normal terms reach the network but the PSD only in stage 2; everything matches finite differences."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from loosefit.models.jointnet import JointNet, JointNetConfig
from tests.models.conftest import central_difference

TINY = JointNetConfig(gru_hidden=6, features=8, bone_mlp=[8], psd_mlp=[6], psd_shapes=3, association="l1",
                      association_radius=0.0, lambda_norm=0.3, lambda_sparse=0.01)
NAMES = ["root", "spine", "neck", "arm_l", "arm_r"]
PARENTS = [-1, 0, 1, 1, 1]
FACES = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4]])
REST = torch.tensor([[0.0, 0.0, 1.0], [0.3, 0.0, 1.0], [0.0, 0.3, 0.9], [0.3, 0.3, 0.8], [0.1, 0.6, 0.8]])


def build(config: JointNetConfig = TINY) -> JointNet:
    torch.manual_seed(0)
    m = JointNet({"num_verts": 5, "num_joints": len(NAMES), "num_faces": 3, "num_bones": 2, "joint_names": NAMES,
                  "parents": PARENTS}, config)
    with torch.no_grad():
        m.faces.copy_(torch.from_numpy(FACES))
        m.rig_rest.copy_(REST)
        m.skin_weights.copy_(torch.tensor([[1.0, 0.0], [0.7, 0.3], [0.5, 0.5], [0.2, 0.8], [0.0, 1.0]]))
        m.bone_rest.copy_(torch.tensor([[0.1, 0.1, 0.95], [0.2, 0.4, 0.8]]))
        m.offset_std.fill_(0.05)
        m.euler_std.fill_(0.2)
        signs = torch.tensor([[0.5, -0.2, 0.3, 0.1, 0.8], [-0.1, 0.4, 0.2, 0.6, -0.3]])  # some bones' joints off
        m.association.copy_(signs[:, :m.association.shape[1]])
    return m.double()


def batch(seed: int = 0, N: int = 2, T: int = 3) -> dict:
    g = torch.Generator().manual_seed(seed)
    verts = REST.double() + 0.05 * torch.randn(N, T, 5, 3, generator=g, dtype=torch.float64)
    return {"root": torch.randn(N, T, 11, generator=g, dtype=torch.float64),
            "joints": torch.randn(N, T, 4, 6, generator=g, dtype=torch.float64), "verts": verts,
            "burn_in": torch.tensor([0, 1])}


def grads_of(m: JointNet, loss: torch.Tensor) -> dict[str, torch.Tensor | None]:
    m.zero_grad(set_to_none=True)
    loss.backward()
    return {n: p.grad for n, p in m.named_parameters()}


def test_sparsity_term_alone_reaches_the_association_only_with_its_closed_form():
    """``d ||relu(A)||_1 / dA`` is 1 where ``A > 0`` and 0 where ``A < 0``; nothing else is touched."""
    m = build()
    grads = grads_of(m, m.sparsity_loss())
    A = m.association.detach()
    torch.testing.assert_close(grads["association"], (A > 0).double(), rtol=0, atol=0)
    assert all(g is None or g.abs().max() == 0 for n, g in grads.items() if n != "association")


def test_hoyer_sparsity_gradient_matches_finite_differences():
    m = build(dataclasses.replace(TINY, association="hoyer"))
    # the term's own gradient against central differences on every entry with a nonzero value
    value = m.sparsity_loss()
    (grad,) = torch.autograd.grad(value, m.association)
    h = 1e-6
    for idx in torch.nonzero(m.association.detach() > 0):
        i, j = idx.tolist()
        with torch.no_grad():
            m.association[i, j] += h
            up = float(m.sparsity_loss())
            m.association[i, j] -= 2 * h
            down = float(m.sparsity_loss())
            m.association[i, j] += h
        assert float(grad[i, j]) == pytest.approx((up - down) / (2 * h), rel=1e-6, abs=1e-9)
    assert float(value.detach()) > 0


@pytest.mark.parametrize("stage", ["stage1", "stage2"])
@pytest.mark.parametrize("term", ["l1", "normal"])
def test_cloth_and_normal_terms_reach_the_network_and_the_psd_only_in_stage_2(stage, term):
    weights = {"l1": {"lambda_norm": 0.0, "lambda_sparse": 0.0}, "normal": {"lambda_sparse": 0.0}}[term]
    m = build(dataclasses.replace(TINY, **weights))
    loss, _ = m.training_loss(batch(), stage)
    grads = grads_of(m, loss)
    for name, grad in grads.items():
        psd = name.startswith(("psd_mlp.", "psd_basis"))
        if psd and stage == "stage1":
            assert grad is None or grad.abs().max() == 0, name
        elif name not in ("fourier_alpha",):
            assert grad is not None and grad.abs().sum() > 0, f"{term} in {stage}: no gradient reaches {name}"


@pytest.mark.parametrize("stage", ["stage1", "stage2"])
def test_total_loss_gradient_matches_central_differences(stage):
    m = build()
    b = batch(1)
    loss, _ = m.training_loss(b, stage)
    grads = grads_of(m, loss)
    checked = 0
    for name, p in m.named_parameters():
        if grads[name] is None:
            continue
        for k in (0, p.numel() - 1):
            numeric = central_difference(lambda: float(m.training_loss(b, stage)[0]), p, k)
            assert float(grads[name].view(-1)[k]) == pytest.approx(numeric, rel=1e-4, abs=1e-8), name
            checked += 1
    assert checked >= 8
