"""SkinnedMesh: skinning against loosefit's own LBS (body rig) and VirtualBones Eq. 1 (free bones); influence limits."""

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.geometry.lbs import pose_skeleton_and_skin
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.io.skinned_mesh import SkinnedMesh, dense_to_sparse, top_influences
from loosefit.rig.virtual_bones import skin_bones


def random_skinned(seed=0, frames=6, joints=9, verts=40, influences=6, free=False, name="garment", fps=24.0):
    """A random skinned mesh: a random hierarchy (or free bones), random rotations, translations and
    ``influences`` distinct joints per vertex with random weights summing to 1."""
    rng = np.random.default_rng(seed)
    parents = np.full(joints, -1) if free else np.array([-1] + [int(rng.integers(0, j)) for j in range(1, joints)])
    rotations = axis_angle_to_matrix(torch.from_numpy(rng.normal(size=(frames, joints, 3)))).numpy()
    indices = np.stack([rng.choice(joints, influences, replace=False) for _ in range(verts)])
    values = rng.random((verts, influences))
    return SkinnedMesh(name, rng.normal(size=(verts, 3)), np.argsort(rng.random((60, verts)), 1)[:, :3],
                       [f"joint{j}" for j in range(joints)], parents, rng.normal(size=(joints, 3)), rotations,
                       rng.normal(size=(frames, joints, 3)), indices, values / values.sum(1, keepdims=True), fps)


def test_body_rig_skins_like_loosefit_lbs():
    """A hierarchy posed as loosefit poses bodies (local offsets = rest offsets) skins as geometry.lbs does."""
    rng = np.random.default_rng(1)
    mesh = random_skinned(seed=1, joints=7)
    rest_joints = mesh.bind_positions.astype(np.float64)
    offsets = mesh.bind_local()
    aa = rng.normal(size=(mesh.num_frames, 7, 3))
    root = rng.normal(size=(mesh.num_frames, 3))
    trans = np.repeat(offsets[None], mesh.num_frames, 0)
    trans[:, 0] = root
    mesh.rotations, mesh.translations = axis_angle_to_matrix(torch.from_numpy(aa)).numpy(), trans
    dense = np.zeros((40, 7))
    np.put_along_axis(dense, mesh.weight_indices, mesh.weight_values, 1)
    expected, _ = pose_skeleton_and_skin(torch.from_numpy(aa), torch.from_numpy(root), torch.from_numpy(rest_joints),
                                         mesh.parents, torch.from_numpy(mesh.rest_verts.astype(np.float64)),
                                         torch.from_numpy(dense))
    assert np.abs(mesh.skin() - expected.numpy()).max() < 1e-6  # float32 weights, float64 arithmetic


def test_free_bones_skin_like_virtual_bones_eq1():
    """Roots at their centroids c with t = R c + T give v = sum_j W_ij (R_j p_i + T_j)."""
    mesh = random_skinned(seed=2, free=True)
    R, T = mesh.rotations, mesh.translations - (mesh.rotations @ mesh.bind_positions.astype(np.float64)[:, :, None])[..., 0]
    dense = np.zeros((40, mesh.num_joints))
    np.put_along_axis(dense, mesh.weight_indices, mesh.weight_values, 1)
    expected = skin_bones(torch.from_numpy(mesh.rest_verts.astype(np.float64)), torch.from_numpy(dense),
                          torch.from_numpy(R), torch.from_numpy(T)).numpy()
    assert np.abs(mesh.skin() - expected).max() < 1e-9
    assert np.abs(mesh.skin([2, 4]) - expected[[2, 4]]).max() < 1e-9


def test_top_influences_keep_the_largest_and_renormalise():
    indices = np.array([[3, 1, 0, 2], [0, 2, 1, 3]])
    values = np.array([[0.1, 0.4, 0.2, 0.3], [0.5, 0.0, 0.5, 0.0]])
    idx, val = top_influences(indices, values, 2)
    assert idx.tolist() == [[1, 2], [0, 1]]
    assert np.allclose(val, [[0.4 / 0.7, 0.3 / 0.7], [0.5, 0.5]]) and val.dtype == np.float32
    idx, val = top_influences(indices[:, :2], values[:, :2], 4)  # fewer than asked: padded with zeros
    assert idx.tolist() == [[1, 3, 0, 0], [0, 0, 0, 0]] and np.allclose(val, [[0.8, 0.2, 0, 0], [1, 0, 0, 0]])
    assert np.abs(random_skinned().limited(4).weight_values.sum(1) - 1).max() < 1e-6
    with pytest.raises(InputError, match="at least 1"):
        top_influences(indices, values, 0)
    with pytest.raises(InputError, match="vertex 1 has no skinning weight"):
        top_influences(indices, np.array([[1.0, 0, 0, 0], [0, 0, 0, 0]]), 2)


def test_dense_to_sparse_round_trips():
    dense = np.array([[0.0, 0.7, 0.3], [1.0, 0.0, 0.0]], np.float32)
    idx, val = dense_to_sparse(dense)
    assert idx.tolist() == [[1, 2], [0, 0]] and np.array_equal(val, np.array([[0.7, 0.3], [1.0, 0.0]], np.float32))


def test_keeping_every_influence_changes_nothing():
    mesh = random_skinned(seed=3)
    assert np.abs(mesh.limited(6).skin() - mesh.skin()).max() < 1e-6
    assert np.abs(mesh.limited(2).skin() - mesh.skin()).max() > 1e-2  # dropping weights moves vertices


@pytest.mark.parametrize("change, problem", [
    (dict(parents=np.array([-1, 2, 0, 1, 1, 1, 1, 1, 1])), "parents must come before their children"),
    (dict(weight_indices=np.full((40, 6), 9)), r"weight indices outside \[0, 9\)"),
    (dict(rotations=np.zeros((0, 9, 3, 3)), translations=np.zeros((0, 9, 3))), "T > 0"),
    (dict(translations=np.full((6, 9, 3), np.nan)), "not finite"),
    (dict(fps=0.0), "fps must be positive"),
])
def test_bad_meshes_are_refused(change, problem):
    mesh = random_skinned()
    fields = {k: getattr(mesh, k) for k in ("name", "rest_verts", "faces", "joint_names", "parents", "bind_positions",
                                            "rotations", "translations", "weight_indices", "weight_values", "fps")}
    with pytest.raises(InputError, match=f"skinned mesh 'garment': .*{problem}"):
        SkinnedMesh(**{**fields, **change})


def test_skinning_is_linear_in_the_weights():
    mesh = random_skinned(seed=5)
    limited = mesh.limited(3)
    delta = limited.dense_weights() - mesh.dense_weights()
    assert np.abs(mesh.skin(weights=delta) - (limited.skin() - mesh.skin())).max() < 1e-9
