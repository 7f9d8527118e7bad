"""The heading and pelvis frames (loosefit.motion.heading): headings against closed form, world <-> canonical round
trips, and what each frame is invariant to."""

import numpy as np
import torch

from loosefit.geometry.rotations import axis_angle_to_matrix
import pytest

from loosefit.errors import InputError
from loosefit.geometry.rotations import matrix_to_axis_angle
from loosefit.motion.heading import heading_angles, heading_frames, motion_frames, rot_z, to_canonical, to_world
from loosefit.motion.motion import Motion
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


def test_the_pelvis_frame_carries_points_with_a_tilted_and_moved_root():
    """The pelvis frame is the root joint's rotation and position; points carried rigidly with the root by any
    rotation ``Q`` (a tilt included) and shift keep their canonical coordinates. The heading frame keeps them
    under a turn about Z only: under the tilt they move (the control)."""
    m = random_motion(seed=3)
    rot, origin = motion_frames(m, "pelvis")
    R = axis_angle_to_matrix(torch.from_numpy(m.rotations[:, 0]).double()).numpy()
    np.testing.assert_allclose(rot, R, atol=1e-12)
    np.testing.assert_allclose(origin, m.translation, atol=1e-6)
    pts = np.random.default_rng(4).normal(size=(m.num_frames, 6, 3)) + m.translation[:, None]
    Q = axis_angle_to_matrix(torch.tensor([0.6, -0.3, 1.1], dtype=torch.float64)).numpy()
    shift = np.array([0.4, -0.2, 0.3])
    carried = m.rotations.copy()
    carried[:, 0] = matrix_to_axis_angle(torch.from_numpy(Q @ R)).numpy()
    moved = Motion(carried, m.translation @ Q.T + shift, m.fps, m.rig, m.joint_names)
    before = to_canonical(pts, *motion_frames(m, "pelvis"))
    after = to_canonical(pts @ Q.T + shift, *motion_frames(moved, "pelvis"))
    assert np.abs(after - before).max() < 1e-5
    tilted = to_canonical(pts @ Q.T + shift, *motion_frames(moved, "heading"))
    assert np.abs(tilted - to_canonical(pts, *heading_frames(m))).max() > 0.1
    raised = to_canonical(pts @ Q.T + shift, *motion_frames(moved, "raised"))
    assert np.abs(raised - to_canonical(pts, *motion_frames(m, "raised"))).max() > 0.1
    with pytest.raises(InputError, match="frame must be one of"):
        motion_frames(m, "chest")


def test_the_raised_frame_is_the_heading_frame_at_the_root_joint():
    """The raised frame turns as the heading frame and sits at the root joint: points carried by a turn about Z and
    any shift, a vertical one included, keep their canonical coordinates; in the heading frame a vertical shift
    moves them by its height."""
    m = random_motion(seed=5)
    rot, origin = motion_frames(m, "raised")
    np.testing.assert_allclose(rot, heading_frames(m)[0], atol=1e-12)
    np.testing.assert_allclose(origin, m.translation, atol=1e-6)
    pts = np.random.default_rng(6).normal(size=(m.num_frames, 6, 3))
    shift = np.array([0.3, -0.4, 0.25])
    moved = turned(m, 1.3, shift)
    Rz = axis_angle_to_matrix(torch.tensor([0.0, 0.0, 1.3], dtype=torch.float64)).numpy()
    before = to_canonical(pts, *motion_frames(m, "raised"))
    assert np.abs(to_canonical(pts @ Rz.T + shift, *motion_frames(moved, "raised")) - before).max() < 1e-5
    lifted = to_canonical(pts @ Rz.T + shift, *heading_frames(moved)) - to_canonical(pts, *heading_frames(m))
    np.testing.assert_allclose(lifted[..., 2], 0.25, atol=1e-5)
