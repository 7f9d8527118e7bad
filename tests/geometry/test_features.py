"""Garment-body indicator, vertex-joint distances and FitGar's relative skinning features."""

import numpy as np
import pytest
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


def test_normal_projection_spreads_a_cone_that_the_closest_point_collapses():
    """Points in the cone of normals at a vertex of an icosahedron (2 m out from a unit one) all have that
    vertex as their closest point; along the interpolated normal field each gets a point of its own, from
    which it lies exactly on the interpolated normal (x = P(b) + t N(b), t > 0)."""
    import trimesh

    from loosefit.geometry.features import closest_body_points, normal_projection_points
    from loosefit.geometry.normals import vertex_normals

    ico = trimesh.creation.icosahedron()
    P, F = np.asarray(ico.vertices, np.float64), np.asarray(ico.faces, np.int64)
    apex = P[0] / np.linalg.norm(P[0])
    side = np.cross(apex, [0.0, 0.0, 1.0] if abs(apex[2]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    up = np.cross(apex, side)
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    dirs = apex + 0.08 * (np.cos(angles)[:, None] * side + np.sin(angles)[:, None] * up)
    x = 3.0 * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    face, bary = closest_body_points(x, P, F)
    closest = np.einsum("vk,vkc->vc", bary, P[F[face]])
    np.testing.assert_allclose(closest, np.tile(P[0], (len(x), 1)), atol=1e-9)
    face, bary = normal_projection_points(x, P, F)
    point = np.einsum("vk,vkc->vc", bary, P[F[face]])
    normal = np.einsum("vk,vkc->vc", bary, vertex_normals(P, F).astype(np.float64)[F[face]])
    t = np.einsum("vc,vc->v", x - point, normal) / np.einsum("vc,vc->v", normal, normal)
    assert (t > 0).all()
    np.testing.assert_allclose(point + t[:, None] * normal, x, atol=1e-6)
    assert cdist(point, point)[np.triu_indices(len(x), 1)].min() > 1e-3


def test_normal_projection_on_a_plane_is_the_orthogonal_projection():
    """All normals equal: the projection along them is the foot of the perpendicular, the closest point."""
    from loosefit.geometry.features import normal_projection_points

    g = np.stack(np.meshgrid(np.linspace(0, 1, 6), np.linspace(0, 1, 6)), -1).reshape(-1, 2)
    P = np.c_[g, np.zeros(len(g))]
    F = np.array([[i * 6 + j, i * 6 + j + 1, (i + 1) * 6 + j + 1] for i in range(5) for j in range(5)]
                 + [[i * 6 + j, (i + 1) * 6 + j + 1, (i + 1) * 6 + j] for i in range(5) for j in range(5)])
    F = F[:, [0, 2, 1]] if np.cross(P[F[0, 1]] - P[F[0, 0]], P[F[0, 2]] - P[F[0, 0]])[2] < 0 else F
    x = np.random.default_rng(0).uniform([0.1, 0.1, 0.05], [0.9, 0.9, 0.5], (20, 3))
    face, bary = normal_projection_points(x, P, F)
    np.testing.assert_allclose(np.einsum("vk,vkc->vc", bary, P[F[face]]), np.c_[x[:, :2], np.zeros(len(x))], atol=1e-9)


def test_spread_moves_coinciding_points_apart_in_the_garment_layout():
    """On a plane: five garment vertices in a row 0.2 mm apart, rising, project within 1 mm of one another; the
    lowest keeps its point, the others move to their offsets scaled to the 2 mm gap, in the row's order (closed
    form). Two vertices stacked along the normal: the upper one moves 2 mm along a triangle's edge. A vertex alone
    keeps its point exactly."""
    from loosefit.geometry.features import closest_body_points, spread_shared_points

    g = np.stack(np.meshgrid(np.linspace(0, 1, 6), np.linspace(0, 1, 6)), -1).reshape(-1, 2)
    P = np.c_[g, np.zeros(len(g))]
    F = np.array([[i * 6 + j, i * 6 + j + 1, (i + 1) * 6 + j + 1] for i in range(5) for j in range(5)]
                 + [[i * 6 + j, (i + 1) * 6 + j + 1, (i + 1) * 6 + j] for i in range(5) for j in range(5)])
    row = np.c_[0.5 + 2e-4 * np.arange(5), np.full(5, 0.47), 0.10 + 0.01 * np.arange(5)]
    x = np.concatenate([row, [[0.23, 0.31, 0.1], [0.23, 0.31, 0.2], [0.81, 0.77, 0.3]]])
    face, bary = closest_body_points(x, P, F)
    spread_face, spread_bary = spread_shared_points(x, P, F, face, bary)
    point = np.einsum("vk,vkc->vc", spread_bary, P[F[spread_face]])
    np.testing.assert_allclose(point[:5], np.c_[0.5 + 2e-3 * np.arange(5), np.full(5, 0.47), np.zeros(5)], atol=1e-12)
    np.testing.assert_allclose(point[5], [0.23, 0.31, 0.0], atol=1e-12)
    assert np.linalg.norm(point[6] - point[5]) == pytest.approx(2e-3, abs=1e-12)
    assert spread_face[7] == face[7] and np.array_equal(spread_bary[7], bary[7])
    assert cdist(point, point)[np.triu_indices(len(x), 1)].min() >= 2e-3 - 1e-12
