"""Rotation conversions: round trips near 0 and pi, Euler orders against scipy, 6D Gram-Schmidt."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from loosefit.geometry.rotations import (
    axis_angle_to_matrix,
    axis_angle_to_quaternion,
    euler_to_matrix,
    matrix_to_axis_angle,
    matrix_to_euler,
    matrix_to_quaternion,
    matrix_to_sixd,
    nearest_rotation,
    quaternion_to_axis_angle,
    quaternion_to_matrix,
    rigid,
    rotation_angle,
    rotation_between,
    sixd_to_matrix,
)

ORDERS = ["xyz", "xzy", "yxz", "yzx", "zxy", "zyx"]


def sample_rotations():
    """Axis-angle vectors with angles at and near 0 and pi, plus random ones (float64)."""
    rng = np.random.default_rng(0)
    axes = rng.normal(size=(8, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.array([0.0, 1e-9, 1e-6, 1e-4, 0.3, 2.0, np.pi - 1e-6, np.pi - 1e-3])
    return torch.from_numpy(np.vstack([axes * angles[:, None], rng.normal(0, 1.2, (20, 3))]))


def same_rotation_vector(a, b):
    """Axis-angle vectors equal, allowing (axis, pi) == (-axis, pi)."""
    close = (a - b).norm(dim=-1) < 1e-6
    at_pi = (a.norm(dim=-1) - np.pi).abs() < 1e-5
    return bool((close | (at_pi & ((a + b).norm(dim=-1) < 1e-5))).all())


def test_axis_angle_matrix_matches_scipy_and_round_trips():
    aa = sample_rotations()
    R = axis_angle_to_matrix(aa)
    assert np.abs(R.numpy() - Rotation.from_rotvec(aa.numpy()).as_matrix()).max() < 1e-12
    assert same_rotation_vector(matrix_to_axis_angle(R), aa)
    exactly_pi = torch.tensor([[0.0, 0.0, np.pi], [np.pi / np.sqrt(2), -np.pi / np.sqrt(2), 0.0]], dtype=torch.float64)
    back = matrix_to_axis_angle(axis_angle_to_matrix(exactly_pi))
    assert same_rotation_vector(back, exactly_pi)
    assert torch.allclose(axis_angle_to_matrix(back), axis_angle_to_matrix(exactly_pi), atol=1e-10)


def test_quaternions_match_scipy_and_round_trip():
    aa = sample_rotations()
    q = axis_angle_to_quaternion(aa)
    ref = Rotation.from_rotvec(aa.numpy()).as_quat()  # (x, y, z, w)
    ref = np.concatenate([ref[:, 3:], ref[:, :3]], 1)
    ref *= np.sign(ref[:, :1] + 1e-300)  # w >= 0
    assert np.abs(q.numpy() - ref).max() < 1e-10
    R = axis_angle_to_matrix(aa)
    assert torch.allclose(quaternion_to_matrix(q), R, atol=1e-10)
    assert torch.allclose(quaternion_to_matrix(matrix_to_quaternion(R)), R, atol=1e-10)
    assert same_rotation_vector(quaternion_to_axis_angle(q), aa)
    assert torch.allclose(quaternion_to_matrix(-q), R, atol=1e-10)  # q and -q: one rotation


@pytest.mark.parametrize("order", ORDERS)
def test_euler_all_orders_against_scipy_intrinsic(order):
    rng = np.random.default_rng(ORDERS.index(order))
    angles = np.stack([rng.uniform(-np.pi, np.pi, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-np.pi, np.pi, 50)], 1)
    R = euler_to_matrix(torch.from_numpy(angles), order)
    assert np.abs(R.numpy() - Rotation.from_euler(order.upper(), angles).as_matrix()).max() < 1e-12
    back = matrix_to_euler(R, order)
    assert np.abs(back.numpy() - angles).max() < 1e-9  # unique in these ranges
    # Gimbal lock (middle angle +-90 degrees): the angles change but the rotation must not.
    locked = torch.tensor([[0.4, np.pi / 2, -0.7], [1.0, -np.pi / 2, 0.2]], dtype=torch.float64)
    R_locked = euler_to_matrix(locked, order)
    assert torch.allclose(euler_to_matrix(matrix_to_euler(R_locked, order), order), R_locked, atol=1e-7)


def test_sixd_round_trip_and_gram_schmidt():
    R = axis_angle_to_matrix(sample_rotations())
    assert torch.allclose(sixd_to_matrix(matrix_to_sixd(R)), R, atol=1e-12)
    raw = torch.from_numpy(np.random.default_rng(5).normal(size=(100, 6)))
    M = sixd_to_matrix(raw)
    eye = torch.eye(3, dtype=M.dtype).expand(100, 3, 3)
    assert torch.allclose(M.transpose(-1, -2) @ M, eye, atol=1e-12)
    assert torch.allclose(torch.linalg.det(M), torch.ones(100, dtype=M.dtype), atol=1e-12)
    assert torch.allclose(M[:, :, 0], raw[:, :3] / raw[:, :3].norm(dim=-1, keepdim=True))


def test_float32_batches_and_rigid():
    aa = torch.randn(4, 5, 3, generator=torch.Generator().manual_seed(0)).float()
    R = axis_angle_to_matrix(aa)
    assert R.shape == (4, 5, 3, 3) and R.dtype == torch.float32
    back = matrix_to_axis_angle(R)
    assert back.dtype == torch.float32 and (axis_angle_to_matrix(back) - R).abs().max() < 1e-5
    T = rigid(R, torch.ones(4, 5, 3))
    assert T.shape == (4, 5, 4, 4) and torch.equal(T[..., 3, :], torch.tensor([0.0, 0, 0, 1]).expand(4, 5, 4))
    with pytest.raises(ValueError, match="permutation"):
        euler_to_matrix(torch.zeros(3), "xxy")


def test_rotation_between_takes_a_to_b_with_the_smallest_angle():
    """The angle equals the angle between the vectors and the axis is perpendicular to both, also
    for parallel and opposite pairs (a half turn whose axis is perpendicular to a)."""
    rng = np.random.default_rng(1)
    a = rng.normal(size=(50, 3))
    b = rng.normal(size=(50, 3))
    a[0], b[0] = [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]
    a[1], b[1] = [0.0, 0.6, 0.8], [0.0, -0.6, -0.8]
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    R = rotation_between(a, b).numpy()
    assert np.abs(np.einsum("nab,nb->na", R, a) - b).max() < 1e-12
    assert np.abs(np.linalg.det(R) - 1).max() < 1e-12
    expected = np.arccos(np.clip((a * b).sum(1), -1, 1))
    assert np.abs(rotation_angle(R).numpy() - expected).max() < 1e-6
    axis = Rotation.from_matrix(R[2:]).as_rotvec()
    assert np.abs((axis * a[2:]).sum(1)).max() < 1e-9 and np.abs((axis * b[2:]).sum(1)).max() < 1e-9


def test_nearest_rotation_is_the_chordal_mean_and_excludes_reflections():
    """Of a rotation it is the rotation itself; of the sum of two rotations about one axis it is the
    rotation halfway; of a reflection's negative (det -1) a proper rotation."""
    R = Rotation.from_rotvec(sample_rotations().numpy()).as_matrix()
    assert np.abs(nearest_rotation(R).numpy() - R).max() < 1e-12
    z = np.array([0.0, 0.0, 1.0])
    pair = Rotation.from_rotvec([0.2 * z, 1.0 * z]).as_matrix().sum(0)
    assert np.abs(nearest_rotation(pair).numpy() - Rotation.from_rotvec(0.6 * z).as_matrix()).max() < 1e-12
    Q = nearest_rotation(-np.eye(3) + 0.01).numpy()
    assert abs(np.linalg.det(Q) - 1) < 1e-12 and np.abs(Q @ Q.T - np.eye(3)).max() < 1e-12


def test_rotation_angle_matches_axis_angle_norm():
    aa = sample_rotations()
    angles = rotation_angle(axis_angle_to_matrix(aa)).numpy()
    norm = np.linalg.norm(aa.numpy(), axis=1) % (2 * np.pi)
    expected = np.minimum(norm, 2 * np.pi - norm)  # an angle beyond pi is the opposite turn
    assert np.abs(angles - expected).max() < 1e-7  # arccos loses digits near 0 and pi
