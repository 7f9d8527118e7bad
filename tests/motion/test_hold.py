import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.motion.hold import hold_poses, settled_frames
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
