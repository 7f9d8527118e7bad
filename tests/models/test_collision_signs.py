"""Neural collision handling's signs and constants (SwinGar Sec. III-D) on closed-form fields: SwinGar Eq. 10
weighs only the neighbours that are not inside, moves along the outward gradient (loosefit's SDF is negative
inside, SwinGar Eq. 7's positive; Eq. 10 alone, without loosefit's surface pass); SwinGar Eqs. 8-9 with ``mu_e = 0.15`` and the Eikonal target 1; the
network's Softplus at beta = 100."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from loosefit.models.collision import (EIKONAL_WEIGHT, SOFTPLUS_BETA, BodySDFConfig, BodySDFNet, CollisionResolver,
                                       resolve_collisions, sdf_loss)

CENTRE, RADIUS = torch.tensor([0.1, -0.2, 0.3], dtype=torch.float64), 0.5


def sphere(x: torch.Tensor) -> torch.Tensor:
    """The exact signed distance of a sphere, negative inside."""
    return (x - CENTRE.to(x.dtype)).norm(dim=-1) - RADIUS


def on_ray(direction, distances) -> torch.Tensor:
    """Points at signed distances ``distances`` from the sphere along the ray from its centre in ``direction``."""
    d = torch.tensor(direction, dtype=torch.float64)
    d = d / d.norm()
    return CENTRE + (RADIUS + torch.tensor(distances, dtype=torch.float64))[:, None] * d


def test_only_free_neighbours_weigh_in_the_correction():
    """One triangle: vertices 0 and 1 inside, 2 outside. Each inside vertex has one free neighbour (vertex 2), so
    ``delta_i = |S(x_2)|`` exactly, whatever the Gaussian weight of the inside neighbour: moved radially by
    ``|S(x_i)| + delta_i``, each lands ``|S(x_2)|`` outside the sphere."""
    verts = torch.cat([on_ray([1.0, 0.2, 0.0], [-0.03]), on_ray([1.0, 0.0, 0.1], [-0.01]),
                       on_ray([1.0, -0.1, -0.1], [0.02])])
    for sigma in (0.01, 0.05, 1.0):  # the inside neighbour would weigh more and more
        out, inside = resolve_collisions(verts, np.array([[0, 1, 2]]), sphere, sigma=sigma, surface=False)
        assert inside.tolist() == [True, True, False]
        torch.testing.assert_close(sphere(out[:2]), torch.full((2,), 0.02, dtype=torch.float64), rtol=1e-9, atol=1e-12)
        assert torch.equal(out[2], verts[2])


def test_a_vertex_without_free_neighbours_lands_on_the_surface():
    """Every neighbour inside: ``delta_i = 0`` (no weights, not an average of inside values) and the vertex moves
    by ``|S(x_i)|`` onto the surface, along the outward gradient."""
    verts = torch.cat([on_ray([0.0, 0.0, 1.0], [-0.05]), on_ray([0.1, 0.0, 1.0], [-0.02]),
                       on_ray([0.0, 0.1, 1.0], [-0.04])])
    out, inside = CollisionResolver(np.array([[0, 1, 2]]), 3, sigma=0.05, surface=False)(verts, sphere)
    assert inside.all()
    torch.testing.assert_close(sphere(out), torch.zeros(3, dtype=torch.float64), rtol=0, atol=1e-12)
    outward = (out - verts) / (out - verts).norm(dim=-1, keepdim=True)
    radial = (verts - CENTRE) / (verts - CENTRE).norm(dim=-1, keepdim=True)
    torch.testing.assert_close(outward, radial, rtol=0, atol=1e-9)


def test_the_correction_magnitude_adds_delta_to_the_depth():
    """``|Delta(x_i)| = |S(x_i)| + delta_i`` (SwinGar Eq. 10): both terms add; the vertex leaves the body by delta."""
    verts = torch.cat([on_ray([0.0, 1.0, 0.0], [-0.04, 0.01, 0.03])])
    sigma = 0.02
    out, inside = resolve_collisions(verts, np.array([[0, 1, 2]]), sphere, sigma=sigma, surface=False)
    d = (verts[1:] - verts[0]).norm(dim=-1)
    w = torch.exp(-d**2 / (2 * sigma**2))
    delta = float((w * torch.tensor([0.01, 0.03], dtype=torch.float64)).sum() / w.sum())
    assert float((out[0] - verts[0]).norm()) == pytest.approx(0.04 + delta, rel=1e-9)
    assert 0.01 < delta < 0.03


def test_sdf_loss_is_eq8_plus_mu_e_times_eq9():
    """``mean(|S - s| + |grad S - n|) + 0.15 mean((|grad S| - 1)^2)``, the gradient by autograd on its own."""
    assert EIKONAL_WEIGHT == 0.15
    torch.manual_seed(0)
    net = BodySDFNet(code_size=2, config=BodySDFConfig(hidden=16, init_radius=0.3)).double()
    g = torch.Generator().manual_seed(1)
    x = torch.randn(20, 3, generator=g, dtype=torch.float64) * 0.4
    target = torch.randn(20, generator=g, dtype=torch.float64) * 0.1
    normals = torch.nn.functional.normalize(torch.randn(20, 3, generator=g, dtype=torch.float64), dim=-1)
    code = torch.randn(2, generator=g, dtype=torch.float64)
    with torch.no_grad():
        net.point[0].weight.mul_(1.7)  # gradients far from unit length: the Eikonal term is large
    loss, terms = sdf_loss(net, x, target, normals, code)
    xr = x.clone().requires_grad_(True)
    s = net(xr, code)
    (grad,) = torch.autograd.grad(s.sum(), xr)
    value = (s.detach() - target).abs().mean()
    normal = (grad - normals).norm(dim=-1).mean()
    eikonal = ((grad.norm(dim=-1) - 1.0) ** 2).mean()
    assert float(eikonal) > 0.05
    assert terms["eikonal"] == pytest.approx(float(eikonal), rel=1e-10)
    assert float(loss.detach()) == pytest.approx(float(value + normal + 0.15 * eikonal), rel=1e-10)
    # mu_e = 0 leaves Eq. 8 alone
    without = float(sdf_loss(net, x, target, normals, code, eikonal=0.0)[0].detach())
    assert without == pytest.approx(float(value + normal), rel=1e-10)


def test_eikonal_term_vanishes_for_a_distance_field_only():
    """``(|grad S| - 1)^2`` is zero where the field's gradient has unit length and grows as ``(k - 1)^2`` when the
    field is a distance scaled by ``k`` (the term's target is 1, not 0)."""
    torch.manual_seed(2)
    net = BodySDFNet(code_size=0, config=BodySDFConfig(hidden=8, point_layers=1, code_layers=1, fusion_layers=1))
    net = net.double()
    with torch.no_grad():
        for k in (1.0, 2.5):
            for layer in [*net.point, *net.code, *net.fusion]:
                layer.weight.zero_()
                layer.bias.zero_()
            # S(x) = k softplus_100(x_0) through one point unit, = k x_0 up to e^-50 for x_0 >= 0.5
            net.point[0].weight[0, 0] = 1.0
            net.fusion[-1].weight[0, 0] = k
            x = torch.rand(10, 3, dtype=torch.float64) + 0.5  # x_0 in [0.5, 1.5]: softplus_100 is linear there
            eik = sdf_loss(net, x, torch.zeros(10, dtype=torch.float64), torch.zeros(10, 3, dtype=torch.float64))[1]
            assert eik["eikonal"] == pytest.approx((k - 1.0) ** 2, abs=1e-12)


def test_softplus_sharpness_is_100():
    """SwinGar Sec. IV: Softplus with beta = 100: ``log(1 + e^{100 z}) / 100``, ``log 2 / 100`` at zero."""
    assert SOFTPLUS_BETA == 100.0
    act = BodySDFNet(0, BodySDFConfig(hidden=4)).act
    z = torch.tensor([-0.05, 0.0, 0.01, 0.2], dtype=torch.float64)
    torch.testing.assert_close(act(z), torch.log1p(torch.exp(100.0 * z)) / 100.0, rtol=1e-12, atol=1e-15)
    assert float(act(torch.zeros(1, dtype=torch.float64))) == pytest.approx(math.log(2.0) / 100.0, rel=1e-12)
