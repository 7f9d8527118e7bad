"""Garment-body indicator, vertex-joint distances and FitGar's relative skinning features."""

import numpy as np
import torch
from scipy.spatial.distance import cdist

from loosefit.geometry.features import (
    indicator_matrix,
    nearest_body_vertex,
    relative_skinning_features,
    vertex_joint_distances,
)
from loosefit.geometry.lbs import forward_kinematics
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion import Motion


def test_nearest_body_vertex_and_indicator_against_brute_force():
    rng = np.random.default_rng(0)
    body = rng.normal(size=(200, 3))
    garment = rng.normal(size=(50, 3))
    idx = nearest_body_vertex(garment, body)
    assert np.array_equal(idx, cdist(garment, body).argmin(1))
    I = indicator_matrix(idx, len(body))
    assert I.shape == (50, 200) and np.array_equal(I.sum(1).A.ravel(), np.ones(50))
    posed = np.stack([body + 1.0, 2 * body])
    assert np.allclose(np.stack([I @ p for p in posed]), posed[:, idx])


def test_vertex_joint_distances_broadcast_over_frames():
    rng = np.random.default_rng(1)
    verts, joints = rng.normal(size=(7, 3)), rng.normal(size=(3, 4, 3))
    d = vertex_joint_distances(verts, joints)
    assert d.shape == (3, 7, 4) and d.dtype == np.float32
    for t in range(3):
        assert np.allclose(d[t], cdist(verts, joints[t]), atol=1e-6)


def two_joint_rig():
    rest_joints = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.5]])
    rng = np.random.default_rng(2)
    verts = rest_joints[0] + rng.normal(0, 0.3, (30, 3))
    w = rng.uniform(size=(30, 2))
    return verts, w / w.sum(1, keepdims=True), rest_joints, np.array([-1, 0])


def world(rot_aa, trans, rest_joints, parents):
    R = axis_angle_to_matrix(torch.as_tensor(rot_aa, dtype=torch.float64))
    return forward_kinematics(R, torch.as_tensor(trans, dtype=torch.float64), torch.as_tensor(rest_joints), parents).numpy()


def test_relative_skinning_features_drop_translation_keep_rotation():
    verts, w, rj, parents = two_joint_rig()
    # Root translated, no rotation: the features are the rest positions.
    G = world(np.zeros((1, 2, 3)), rj[0][None] + [[0.4, -2.0, 0.3]], rj, parents)
    assert np.abs(relative_skinning_features(verts, w, G, rj)[0] - verts).max() < 1e-6
    # Root turned 90 degrees about Z and translated, child still: a rigid turn about the rest root.
    G = world([[[0, 0, np.pi / 2], [0, 0, 0]]], rj[0][None] + [[1.0, 1.0, 0.0]], rj, parents)
    Rz = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    assert np.abs(relative_skinning_features(verts, w, G, rj)[0] - ((verts - rj[0]) @ Rz.T + rj[0])).max() < 1e-6
    # Child bent: the two joints blend, and the vertex closest to the child follows it most.
    G = world([[[0, 0, 0], [np.pi / 2, 0, 0]]], rj[0][None], rj, parents)
    f = relative_skinning_features(verts, w, G, rj)[0]
    Rx = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])
    expected = w[:, :1] * verts + w[:, 1:] * ((verts - rj[1]) @ Rx.T + rj[1])
    assert np.abs(f - expected).max() < 1e-6


def test_relative_skinning_features_on_the_body_ignore_root_translation(proxy_body):
    rng = np.random.default_rng(4)
    rot = rng.normal(0, 0.3, (3, proxy_body.num_joints, 3))
    trans = proxy_body.rest_root_position() + rng.normal(0, 0.5, (3, 3))
    feats = []
    for shift in ([0, 0, 0], [3.0, -1.0, 0.2]):
        motion = Motion(rot, trans + shift, joint_names=proxy_body.joint_names, rig=proxy_body.rig)
        posed = proxy_body.pose(motion)
        feats.append(relative_skinning_features(proxy_body.rest_verts(), proxy_body.skinning_weights(), posed.joint_transforms, proxy_body.rest_joints()))
        # Equal to the posed body moved so that its root sits at the rest root.
        moved = posed.verts - (posed.joints[:, :1] - proxy_body.rest_root_position())
        assert np.abs(feats[-1] - moved).max() < 1e-4
    assert np.abs(feats[0] - feats[1]).max() < 1e-4
