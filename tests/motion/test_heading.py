"""The heading frame (loosefit.motion.heading): headings against closed form, world <-> canonical round trips."""

import numpy as np
import torch

from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion.heading import heading_angles, heading_frames, rot_z, to_canonical, to_world
from tests.models.test_motion_features import random_motion, turned


def test_heading_of_a_turned_and_tilted_root_is_the_turn():
    """A root turned by ``psi`` about Z after any roll about the forward axis (Y) and a small pitch (X) has
    heading ``psi`` (wrapped to (-pi, pi]); ``rot_z`` is the axis-angle rotation about Z."""
    rng = np.random.default_rng(0)
    psi = rng.uniform(-np.pi, np.pi, 50)
    roll, pitch = rng.uniform(-1.2, 1.2, 50), rng.uniform(-0.4, 0.4, 50)
    Rz = axis_angle_to_matrix(torch.from_numpy(np.stack([0 * psi, 0 * psi, psi], 1))).numpy()
    Ry = axis_angle_to_matrix(torch.from_numpy(np.stack([0 * roll, roll, 0 * roll], 1))).numpy()
    Rx = axis_angle_to_matrix(torch.from_numpy(np.stack([pitch, 0 * pitch, 0 * pitch], 1))).numpy()
    np.testing.assert_allclose(rot_z(psi), Rz, atol=1e-12)
    np.testing.assert_allclose(heading_angles(Rz @ Ry), psi, atol=1e-9)  # roll keeps the forward axis
    # pitch tips the forward axis up or down, not sideways: its horizontal projection still points along psi
    np.testing.assert_allclose(heading_angles(Rz @ Rx), psi, atol=1e-9)


def test_canonical_round_trip_and_invariance():
    m = random_motion(seed=1)
    rng = np.random.default_rng(2)
    pts = rng.normal(size=(m.num_frames, 7, 3))
    rot, origin = heading_frames(m)
    canon = to_canonical(pts, rot, origin)
    assert np.abs(to_world(canon, rot, origin) - pts).max() < 1e-5
    assert np.abs(to_world(torch.from_numpy(canon), rot, origin).numpy() - pts).max() < 1e-5
    # Points carried along with a turned and shifted body keep their canonical coordinates.
    m2 = turned(m, -2.0, [0.5, 0.3, 0.0])
    Rz = axis_angle_to_matrix(torch.tensor([0.0, 0.0, -2.0], dtype=torch.float64)).numpy()
    rot2, origin2 = heading_frames(m2)
    assert np.abs(to_canonical(pts @ Rz.T + [0.5, 0.3, 0.0], rot2, origin2) - canon).max() < 1e-5
    assert np.allclose(origin[:, 2], 0)
