import numpy as np
import torch

from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion.motion import Motion
from loosefit.sim.attach import garment_weights, skin_garment
from loosefit.sim.preroll import preroll_frames, start_pose, with_preroll


def _motion(body, frames=4):
    rng = np.random.default_rng(3)
    rot = rng.normal(scale=0.3, size=(frames, body.num_joints, 3)).astype(np.float32)
    rot[:, 0] = [0.2, -0.1, 2.0]  # a tilted root facing about 115 degrees away
    trans = np.tile(np.array([1.0, 2.0, 0.9], np.float32), (frames, 1))
    return Motion(rot, trans, 30.0, body.rig, body.joint_names, "test")


def _matrices(aa):
    return axis_angle_to_matrix(torch.from_numpy(np.asarray(aa, np.float64))).numpy()


def test_preroll_starts_at_rest_under_the_first_frame_and_ends_on_it(body):
    motion = _motion(body)
    assert preroll_frames(1.0, 30.0) == 30
    full = with_preroll(body, motion, 15)
    assert full.num_frames == 15 + motion.num_frames
    np.testing.assert_array_equal(full.rotations[15:], motion.rotations)
    # Start: rest pose (no joint rotation) turned to the first frame's heading, at rest height.
    np.testing.assert_allclose(full.rotations[0, 1:], 0.0)
    R0 = _matrices(motion.rotations[0, 0])
    heading = np.arctan2(R0[1, 0], R0[0, 0])
    np.testing.assert_allclose(_matrices(full.rotations[0, 0]), _matrices([0.0, 0.0, heading]), atol=1e-6)
    np.testing.assert_allclose(full.translation[0], [1.0, 2.0, body.rest_root_position()[2]], atol=1e-6)
    root, trans = start_pose(body, motion)
    np.testing.assert_allclose(trans, full.translation[0], atol=1e-6)
    # The blend ends after two thirds (10 frames); the rest holds the first frame.
    for k in range(10, 15):
        np.testing.assert_allclose(_matrices(full.rotations[k]), _matrices(motion.rotations[0]), atol=1e-5)
        np.testing.assert_allclose(full.translation[k], motion.translation[0], atol=1e-6)
    # Smooth: the root moves monotonically towards the first frame.
    gap = np.linalg.norm(_matrices(full.rotations[:11, 0]) - R0, axis=(1, 2))
    assert np.all(np.diff(gap) <= 1e-6)


def test_garment_start_state_is_a_rigid_move_of_the_rest_garment(body, skirt):
    full = with_preroll(body, _motion(body), 15)
    posed = skin_garment(skirt.verts, garment_weights(skirt.verts, body), body, full.slice(0, 1))[0]
    i, j = np.random.default_rng(0).integers(0, len(skirt.verts), (2, 500))
    rest_d = np.linalg.norm(skirt.verts[i] - skirt.verts[j], axis=1)
    np.testing.assert_allclose(np.linalg.norm(posed[i] - posed[j], axis=1), rest_d, atol=1e-5)
