"""Forward kinematics and LBS against hand-computed chains and rigid transforms."""

import numpy as np
import pytest
import torch

from loosefit.geometry.lbs import (
    forward_kinematics,
    linear_blend_skinning,
    pose_skeleton_and_skin,
    skinning_transforms,
    topological_order,
)
from loosefit.geometry.rotations import axis_angle_to_matrix

RZ90 = torch.tensor([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=torch.float64)


def test_one_bone_is_a_rigid_transform():
    rng = np.random.default_rng(0)
    rest = torch.from_numpy(rng.normal(size=(20, 3)))
    rest_joint = torch.tensor([[0.1, 0.2, 0.9]], dtype=torch.float64)
    aa = torch.from_numpy(rng.normal(size=(3, 1, 3)))
    trans = torch.from_numpy(rng.normal(size=(3, 3)))
    world = forward_kinematics(axis_angle_to_matrix(aa), trans, rest_joint, [-1])
    out = linear_blend_skinning(rest, torch.ones(20, 1, dtype=torch.float64), skinning_transforms(world, rest_joint))
    R = axis_angle_to_matrix(aa[:, 0])
    expected = (R[:, None] @ (rest - rest_joint)[None, ..., None])[..., 0] + trans[:, None]
    assert out.shape == (3, 20, 3) and torch.allclose(out, expected, atol=1e-12)


def test_two_joint_chain_by_hand():
    rest_joints = torch.tensor([[0.0, 0, 0], [1, 0, 0]], dtype=torch.float64)
    local = torch.stack([RZ90, RZ90])[None]  # both joints turn 90 degrees about Z
    trans = torch.tensor([[0.0, 0, 2]], dtype=torch.float64)
    world = forward_kinematics(local, trans, rest_joints, [-1, 0])
    assert torch.allclose(world[0, 1, :3, 3], torch.tensor([0.0, 1, 2], dtype=torch.float64))  # child moved by the root
    assert torch.allclose(world[0, 1, :3, :3], RZ90 @ RZ90)  # 180 degrees
    verts = torch.tensor([[2.0, 0, 0], [0.5, 0, 0]], dtype=torch.float64)
    weights = torch.tensor([[0.0, 1.0], [0.5, 0.5]], dtype=torch.float64)
    out = linear_blend_skinning(verts, weights, skinning_transforms(world, rest_joints))[0]
    assert torch.allclose(out[0], torch.tensor([-1.0, 1, 2], dtype=torch.float64))  # 1 m past the child, turned 180
    # Half root (0, 0.5, 2), half child (0.5 behind the child: (0.5, 1, 2)).
    assert torch.allclose(out[1], torch.tensor([0.25, 0.75, 2], dtype=torch.float64))


def test_rest_pose_reproduces_rest_mesh_and_parent_order():
    rng = np.random.default_rng(1)
    parents = np.array([2, -1, 1, 2])  # root is joint 1, joint 0's parent comes later in the list
    order = topological_order(parents)
    assert order[0] == 1 and list(order).index(2) < list(order).index(0)
    rest_joints = torch.from_numpy(rng.normal(size=(4, 3)))
    verts = torch.from_numpy(rng.normal(size=(10, 3)))
    w = torch.from_numpy(rng.dirichlet(np.ones(4), 10))
    out, world = pose_skeleton_and_skin(torch.zeros(2, 4, 3, dtype=torch.float64), rest_joints[1].expand(2, 3), rest_joints, parents, verts, w)
    assert torch.allclose(out, verts.expand(2, 10, 3), atol=1e-12)
    assert torch.allclose(world[..., :3, 3], rest_joints.expand(2, 4, 3), atol=1e-12)
    with pytest.raises(ValueError, match="cycle"):
        topological_order(np.array([1, 0]))
