"""Where the gradient of each VirtualBones training stage goes, on a tiny float64 model (no store): the
low stage's terms reach the low-frequency module only, the high stage's terms the high-frequency module only
(the low-frequency module is frozen there), and both match central finite differences."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from loosefit.models.layers.edge_conv import neighbour_table
from loosefit.models.virtualbones import VirtualBones, VirtualBonesConfig
from tests.models.conftest import central_difference

# no pose noise: a loss drawn anew at each evaluation has no central difference
TINY = VirtualBonesConfig(lf_hidden=6, hf_hidden=6, global_channels=2, edge_channels=(4,), bone_weight=0.5,
                          collision_weight=3.0, collision_margin=0.01, pose_noise=0.0)
QUAD = np.array([[0, 1, 2], [1, 3, 2]])
SIZES = {"num_verts": 4, "num_joints": 3, "num_faces": 2, "num_bones": 2, "max_degree": 3}


def model(config: VirtualBonesConfig = TINY) -> VirtualBones:
    torch.manual_seed(0)
    m = VirtualBones(SIZES, config)
    with torch.no_grad():
        m.faces.copy_(torch.from_numpy(QUAD))
        m.neighbours.copy_(torch.from_numpy(neighbour_table(QUAD, 4)))
        m.rest_verts.copy_(torch.tensor([[0.0, 0.0, 1.0], [0.2, 0.0, 0.9], [0.0, 0.3, 0.7], [-0.4, 0.0, 0.5]]))
        m.skin_weights.copy_(torch.tensor([[0.8, 0.2], [0.6, 0.4], [0.3, 0.7], [0.0, 1.0]]))
        m.bone_rest.copy_(torch.tensor([[0.1, 0.2, 0.9], [-0.3, 0.0, 0.5]]))
        m.position_mean.copy_(m.bone_rest)
        m.position_std.fill_(0.05)
        m.offset_std.fill_(0.01)
        m.lf_mean.copy_(torch.tensor([0.0, 0.0, 0.8]))
    return m.double()


def batch(seed: int = 0, N: int = 2, T: int = 4) -> dict:
    g = torch.Generator().manual_seed(seed)
    rest = torch.tensor([[0.0, 0.0, 1.0], [0.2, 0.0, 0.9], [0.0, 0.3, 0.7], [-0.4, 0.0, 0.5]], dtype=torch.float64)
    lf = rest + 0.03 * torch.randn(N, T, 4, 3, generator=g, dtype=torch.float64)
    verts = lf + 0.01 * torch.randn(N, T, 4, 3, generator=g, dtype=torch.float64)
    body = verts[..., :2, :] + 0.005 * torch.randn(N, T, 2, 3, generator=g, dtype=torch.float64)
    normals = torch.nn.functional.normalize(torch.randn(N, T, 2, 3, generator=g, dtype=torch.float64), dim=-1)
    return {"root": torch.randn(N, T, 11, generator=g, dtype=torch.float64),
            "joints": torch.randn(N, T, 2, 6, generator=g, dtype=torch.float64), "verts": verts, "lf": lf,
            "bone_rot": torch.eye(3, dtype=torch.float64).expand(N, T, 2, 3, 3),
            "bone_trans": 0.02 * torch.randn(N, T, 2, 3, generator=g, dtype=torch.float64),
            "body": body, "body_normals": normals, "body_nearest": torch.tensor([0, 1, 0, 1]).expand(N, T, 4),
            "burn_in": torch.tensor([0, 1])}


def gradients(m: VirtualBones, stage: str, b: dict) -> dict[str, torch.Tensor | None]:
    m.zero_grad(set_to_none=True)
    loss, _ = m.training_loss(b, stage)
    loss.backward()
    return {n: p.grad for n, p in m.named_parameters()}


@pytest.mark.parametrize("stage", ["low", "high"])
def test_each_stage_trains_exactly_its_own_module(stage):
    m = model()
    own = {n for n, p in m.named_parameters() if any(p is q for q in m.stage_parameters(stage))}
    grads = gradients(m, stage, batch())
    for name, grad in grads.items():
        if name in own:
            assert grad is not None and grad.abs().sum() > 0, f"{stage}: no gradient reaches {name}"
        else:
            assert grad is None or grad.abs().max() == 0, f"{stage}: the gradient reaches {name}"
    assert own and len(own) < len(grads)


@pytest.mark.parametrize("stage, weights", [("low", {"bone_weight": 0.0, "laplacian_weight": 0.0}),
                                            ("low", {"bone_weight": 0.0}), ("low", {"laplacian_weight": 0.0}),
                                            ("high", {"collision_weight": 0.0}), ("high", {})])
def test_stage_loss_gradient_matches_central_differences(stage, weights):
    """On a few entries of the stage's parameters, the gradient of the stage's loss (with its terms switched
    on and off by their weights) against ``(f(p + h) - f(p - h)) / 2h``."""
    m = model(dataclasses.replace(TINY, **weights))
    b = batch(1)
    params = list(m.stage_parameters(stage))
    grads = gradients(m, stage, b)
    by_id = {id(p): grads[n] for n, p in m.named_parameters()}
    checked = 0
    for p in params[:: max(1, len(params) // 4)]:
        for k in (0, p.numel() // 2, p.numel() - 1):
            numeric = central_difference(lambda: float(m.training_loss(b, stage)[0]), p, k)
            assert float(by_id[id(p)].view(-1)[k]) == pytest.approx(numeric, rel=1e-4, abs=1e-8)
            checked += 1
    assert checked >= 6
