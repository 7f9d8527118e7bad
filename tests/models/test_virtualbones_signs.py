"""VirtualBones' signs and constants on closed forms (no data store): a zero network output is the rest
rotation at the mean bone position, a bone rotates about its rest centroid, the Laplacian term of VirtualBones
Eq. 2 on one moved vertex, and the collision term of Sec. 4.3 (``max(-n . (v - b), 0)``) on a plane."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.geometry.rotations import axis_angle_to_matrix, matrix_to_sixd
from loosefit.models.virtualbones import IDENTITY_6D, VirtualBones, VirtualBonesConfig
from loosefit.train.losses import collision_loss, laplacian_difference, laplacian_operator

TINY = VirtualBonesConfig(lf_hidden=8, hf_hidden=8, global_channels=2, edge_channels=(4,))
#: Two triangles sharing the edge (1, 2): vertices 1 and 2 have three neighbours, 0 and 3 two.
QUAD = np.array([[0, 1, 2], [1, 3, 2]])


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    model = VirtualBones({"num_verts": 4, "num_joints": 3, "num_faces": 2, "num_bones": 2, "max_degree": 3}, TINY)
    with torch.no_grad():
        model.bone_rest.copy_(torch.tensor([[0.1, 0.2, 0.9], [-0.3, 0.0, 0.5]]))
        model.position_mean.copy_(torch.tensor([[0.15, 0.2, 0.95], [-0.3, 0.1, 0.5]]))
        model.position_std.copy_(torch.tensor([0.02, 0.03, 0.04]))
    return model.double()


def test_zero_output_is_the_rest_rotation_at_the_mean_position(model):
    """The 6D rotation is a residual on the identity (its first two columns, ``(1, 0, 0), (0, 1, 0)``), and the
    position an offset from the bone's mean position in pooled standard deviations: a zero output gives ``R = I``
    and ``T = mean - c``."""
    assert IDENTITY_6D == (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    R, T = model.decode_bones(torch.zeros(2, 9, dtype=torch.float64))
    torch.testing.assert_close(R, torch.eye(3, dtype=torch.float64).expand(2, 3, 3), rtol=0, atol=1e-15)
    torch.testing.assert_close(T, model.position_mean - model.bone_rest, rtol=0, atol=1e-15)


def test_a_bone_rotates_about_its_rest_centroid(model):
    """``T_j = c'_j - R_j c_j``: the rest centroid ``c_j`` goes to ``c'_j = mean + offset * std`` whatever the
    rotation; a point ``c_j + u`` goes to ``c'_j + R_j u``."""
    rot = axis_angle_to_matrix(torch.tensor([[0.0, 0.0, 0.7], [0.4, -0.2, 0.1]], dtype=torch.float64))
    offset = torch.tensor([[1.0, -2.0, 0.5], [0.0, 3.0, -1.0]], dtype=torch.float64)
    raw = torch.cat([matrix_to_sixd(rot) - torch.tensor(IDENTITY_6D, dtype=torch.float64), offset], -1)
    R, T = model.decode_bones(raw)
    torch.testing.assert_close(R, rot, rtol=0, atol=1e-12)
    target = model.position_mean + offset * model.position_std
    c = model.bone_rest
    torch.testing.assert_close((R @ c[:, :, None])[..., 0] + T, target, rtol=0, atol=1e-12)
    u = torch.tensor([0.05, -0.02, 0.01], dtype=torch.float64)
    torch.testing.assert_close((R @ (c + u)[:, :, None])[..., 0] + T, target + rot @ u, rtol=0, atol=1e-12)
    torch.testing.assert_close(model.encode_bones(R, T), raw, rtol=0, atol=1e-12)


def test_laplacian_term_of_one_moved_vertex():
    """VirtualBones Eq. 2's second term, ``mean_i |L(pred)_i - L(target)_i|`` with the uniform Laplacian
    ``(L x)_i = sum_{j ~ i} (x_j - x_i)``: moving vertex 1 (three neighbours) by ``d`` changes ``L`` by ``-3 d``
    at vertex 1 and by ``+d`` at each neighbour: ``(3 + 3) |d| / 4``. A translation costs nothing."""
    verts = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])[None, None]
    L = laplacian_operator(QUAD, 4)
    moved = verts.clone()
    moved[..., 1, :] += torch.tensor([0.0, 0.03, 0.04])  # |d| = 5 cm
    assert float(laplacian_difference(moved, verts, L)) == pytest.approx(6 * 0.05 / 4, rel=1e-6)
    assert float(laplacian_difference(moved + 0.2, moved, L)) < 1e-7


def test_collision_term_is_the_depth_below_the_body_normal():
    """Sec. 4.3: ``max(-n_k . (v_i - b_k), 0)`` (plus loosefit's ``margin``): zero outside, the depth inside;
    with the normal reversed the sides swap."""
    heights = torch.tensor([-0.02, -0.005, 0.0, 0.01])
    pred = torch.zeros(1, 1, 4, 3)
    pred[..., 2] = heights
    body = torch.zeros(1, 1, 1, 3)
    up = torch.tensor([0.0, 0.0, 1.0]).expand(1, 1, 1, 3)
    nearest = torch.zeros(1, 1, 4, dtype=torch.long)
    assert float(collision_loss(pred, body, up, nearest)) == pytest.approx((0.02 + 0.005) / 4, rel=1e-6)
    assert float(collision_loss(pred, body, -up, nearest)) == pytest.approx(0.01 / 4, rel=1e-6)
    margin = 0.004  # a vertex less than the margin outside counts too
    expected = (0.024 + 0.009 + 0.004 + 0.0) / 4
    assert float(collision_loss(pred, body, up, nearest, margin=margin)) == pytest.approx(expected, rel=1e-6)
