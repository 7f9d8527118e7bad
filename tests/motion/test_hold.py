import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.geometry.rotations import axis_angle_to_matrix, axis_angle_to_quaternion, matrix_to_axis_angle
from loosefit.motion.hold import hold_poses, rest_under, settled_frames
from loosefit.motion.motion import Motion


def _turning(frames: int) -> Motion:
    """Two joints: the root turns about z by 0.1 rad a frame and walks 1 cm a frame along x; the second joint
    bends about x by 0.05 rad a frame."""
    t = np.arange(frames, dtype=np.float64)
    rotations = np.zeros((frames, 2, 3))
    rotations[:, 0, 2] = 0.1 * t
    rotations[:, 1, 0] = 0.05 * t
    translation = np.stack([0.01 * t, np.zeros(frames), np.full(frames, 0.9)], axis=1)
    return Motion(rotations, translation, 30.0, "test", ["root", "knee"], "turning")


def test_held_poses_against_closed_form():
    """About a fixed axis, slerp interpolates the angle linearly: every frame of the result is known exactly."""
    source, every, transition, hold = _turning(10), 3, 4, 2
    held = hold_poses(source, every, transition, hold)
    keys = np.arange(0, 10, every)  # frames 0, 3, 6, 9
    assert held.num_frames == len(keys) * (transition + hold) and held.fps == source.fps
    fraction = np.concatenate([np.arange(1, transition + 1) / transition, np.ones(hold)])
    for k, key in enumerate(keys):
        previous = keys[max(k - 1, 0)]
        block = slice(k * (transition + hold), (k + 1) * (transition + hold))
        expected_frame = previous + fraction * (key - previous)  # source time of every frame of the block
        np.testing.assert_allclose(held.rotations[block, 0, 2], 0.1 * expected_frame, atol=1e-6)
        np.testing.assert_allclose(held.rotations[block, 1, 0], 0.05 * expected_frame, atol=1e-6)
        np.testing.assert_allclose(held.translation[block, 0], 0.01 * expected_frame, atol=1e-7)
    settled = settled_frames(held.num_frames, transition, hold)
    assert settled.tolist() == [5, 11, 17, 23]
    np.testing.assert_allclose(held.rotations[settled], source.rotations[keys], atol=1e-6)
    np.testing.assert_allclose(held.translation[settled], source.translation[keys], atol=1e-7)
    # the frames before a settled one are the same pose: the body stands still while the cloth settles
    np.testing.assert_array_equal(held.rotations[settled - 1], held.rotations[settled])
    in_place = hold_poses(source, every, transition, hold, in_place=True)
    np.testing.assert_array_equal(in_place.rotations, held.rotations)
    np.testing.assert_array_equal(in_place.translation[:, :2], np.broadcast_to(source.translation[0, :2], (24, 2)))
    np.testing.assert_array_equal(in_place.translation[:, 2], held.translation[:, 2])


def test_hold_arguments_are_checked():
    for kwargs in ({"every": 0, "transition": 1, "hold": 1}, {"every": 2, "transition": 0, "hold": 1},
                   {"every": 2, "transition": 1, "hold": 2.5}):
        with pytest.raises(InputError, match="must be an integer >= 1"):
            hold_poses(_turning(5), **kwargs)
    with pytest.raises(InputError, match="'order_seed' must be None or an integer >= 0"):
        hold_poses(_turning(5), 2, 1, 1, order_seed=-1)


def test_from_rest_reaches_every_key_from_the_rest_pose():
    """With ``from_rest`` the targets alternate: the rest pose under each key (here the root only turns about
    z, so its rest keeps the key's root; the knee is straight; the root at the first key's height), then the
    key; each is reached in a linear ramp of the angle and held."""
    source, every, transition, hold = _turning(10), 3, 4, 2
    source.translation[:, 2] += 0.02 * np.arange(10)  # the root rises 2 cm a frame
    held = hold_poses(source, every, transition, hold, from_rest=True)
    keys = np.arange(0, 10, every)
    half = transition + hold
    assert held.num_frames == 2 * len(keys) * half
    ramp = np.concatenate([np.arange(1, transition + 1) / transition, np.ones(hold)])
    for k, key in enumerate(keys):
        previous = keys[max(k - 1, 0)]
        to_rest = slice(2 * k * half, (2 * k + 1) * half)
        to_key = slice((2 * k + 1) * half, (2 * k + 2) * half)
        # going to the rest: the root turns on from the previous key, the knee straightens from it
        root_time = previous + ramp * (key - previous) if k else np.zeros(half)
        np.testing.assert_allclose(held.rotations[to_rest, 0, 2], 0.1 * root_time, atol=1e-6)
        np.testing.assert_allclose(held.rotations[to_rest, 1, 0], 0.05 * previous * (1 - ramp) if k else 0,
                                   atol=1e-6)
        np.testing.assert_allclose(held.translation[to_rest, 0], 0.01 * root_time, atol=1e-7)
        height = 0.9 + 0.02 * previous * (1 - ramp) if k else np.full(half, 0.9)  # down to the first key's
        np.testing.assert_allclose(held.translation[to_rest, 2], height, atol=1e-7)
        np.testing.assert_allclose(held.translation[to_key, 2], 0.9 + 0.02 * key * ramp, atol=1e-7)
        # going to the key: the root stays, the knee bends from straight
        np.testing.assert_allclose(held.rotations[to_key, 0, 2], 0.1 * key, atol=1e-6)
        np.testing.assert_allclose(held.rotations[to_key, 1, 0], 0.05 * key * ramp, atol=1e-6)
        np.testing.assert_allclose(held.translation[to_key, 0], 0.01 * key, atol=1e-7)
    settled = settled_frames(held.num_frames, transition, hold, from_rest=True)
    assert settled.tolist() == [11, 23, 35, 47]
    np.testing.assert_allclose(held.rotations[settled], source.rotations[keys], atol=1e-6)
    np.testing.assert_allclose(held.rotations[settled - half, 1], 0.0, atol=1e-7)  # the settled rest


def test_rest_under_keeps_only_the_heading():
    """A root pitched forward by 0.3 rad and turned by psi about z rests turned by psi alone (the rest forward
    is -Y); every other joint rests unrotated."""
    psi = np.array([0.0, 0.7, -2.5])
    pitch = axis_angle_to_matrix(torch.tensor([0.3, 0.0, 0.0], dtype=torch.float64))
    yaw = axis_angle_to_matrix(torch.from_numpy(np.stack([0 * psi, 0 * psi, psi], 1)))
    root = matrix_to_axis_angle(yaw @ pitch).numpy()
    keys = np.tile(np.array([0.9, 0.1, 0.3, -0.3]), (3, 2, 1))
    rest = rest_under(keys, root)
    expected = axis_angle_to_quaternion(torch.from_numpy(np.stack([0 * psi, 0 * psi, psi], 1))).numpy()
    np.testing.assert_allclose(rest[:, 0], expected, atol=1e-12)
    np.testing.assert_array_equal(rest[:, 1], np.tile([1.0, 0, 0, 0], (3, 1)))


def test_an_order_seed_visits_the_same_keys_in_another_order():
    source, every, transition, hold = _turning(20), 3, 4, 2
    keys = np.arange(0, 20, every)
    order = np.random.default_rng(5).permutation(keys)
    assert not np.array_equal(order, keys)
    for from_rest in (False, True):
        held = hold_poses(source, every, transition, hold, from_rest=from_rest, order_seed=5)
        settled = settled_frames(held.num_frames, transition, hold, from_rest=from_rest)
        np.testing.assert_allclose(held.rotations[settled], source.rotations[order], atol=1e-6)
        np.testing.assert_allclose(held.translation[settled], source.translation[order], atol=1e-6)
    # the first target moves from itself; then each key is reached from the one visited before it
    held = hold_poses(source, every, transition, hold, order_seed=5)
    ramp = np.arange(1, transition + 1) / transition
    block = slice(transition + hold, transition + hold + transition)
    np.testing.assert_allclose(held.rotations[block, 1, 0], 0.05 * (order[0] + ramp * (order[1] - order[0])), atol=1e-6)
