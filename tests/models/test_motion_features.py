"""Motion features in the heading frame: invariance, history, streaming."""

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.models.motion_features import (
    HISTORY_FRAMES,
    HISTORY_ROOT_FEATURES,
    ROOT_FEATURES,
    FeatureStream,
    MotionHistory,
    check_history,
    motion_features,
)
from loosefit.motion import Motion
from loosefit.motion.heading import heading_frames


def turned(motion: Motion, yaw: float, shift) -> Motion:
    """The same motion turned about Z by ``yaw`` and moved by ``shift`` (world)."""
    Rz = axis_angle_to_matrix(torch.tensor([0.0, 0.0, yaw], dtype=torch.float64)).numpy()
    rot = motion.rotations.copy()
    root = axis_angle_to_matrix(torch.from_numpy(rot[:, 0]).double()).numpy()
    from loosefit.geometry.rotations import matrix_to_axis_angle

    rot[:, 0] = matrix_to_axis_angle(torch.from_numpy(Rz @ root)).numpy()
    trans = motion.translation @ Rz.T + np.asarray(shift)
    return Motion(rot, trans, motion.fps, motion.rig, motion.joint_names)


def random_motion(T=20, J=5, seed=0):
    rng = np.random.default_rng(seed)
    rot = np.cumsum(rng.normal(0, 0.1, (T, J, 3)), 0)
    trans = np.cumsum(rng.normal(0, 0.05, (T, 3)), 0) + [0, 0, 0.9]
    return Motion(rot, trans, rig="test")


HISTORIES = [None, MotionHistory(), MotionHistory((2.5, 60.0)), MotionHistory(HISTORY_FRAMES, vertical=True)]


@pytest.mark.parametrize("history", HISTORIES)
def test_features_are_invariant_to_heading_and_position(history):
    m = random_motion()
    a = motion_features(m, history)
    b = motion_features(turned(m, 1.3, [2.0, -1.0, 0.0]), history)
    count = ROOT_FEATURES if history is None else ROOT_FEATURES + (4 if history.vertical else 3) * len(history.frames)
    assert a["root"].shape[1] == count == (history.root_features if history else ROOT_FEATURES)
    for key in a:
        assert np.abs(a[key] - b[key]).max() < 1e-5


def test_history_is_the_weighted_sum_of_the_past():
    """Each average against its closed form ``sum_k (1 - a) a^(t-k) x_k`` (the heading change; the world
    horizontal displacement turned into frame t's heading frame; the vertical displacement), and a steady turn's
    average against ``w (1 - a^t)``."""
    m = random_motion(T=40, seed=4)
    history = MotionHistory((*HISTORY_FRAMES, 60.0), vertical=True)
    plain, f = motion_features(m)["root"], motion_features(m, history)["root"]
    assert np.array_equal(f[:, :ROOT_FEATURES], plain)
    default = motion_features(m, MotionHistory())["root"]
    assert default.shape[1] == HISTORY_ROOT_FEATURES
    rot, _ = heading_frames(m)
    disp = np.diff(m.translation, axis=0, prepend=m.translation[:1])
    for i, tau in enumerate(history.frames):
        a = np.exp(-1 / tau)
        k = ROOT_FEATURES + 4 * i
        for t in (0, 7, 39):
            w = (1 - a) * a ** (t - np.arange(t + 1))
            assert abs(f[t, k] - w @ plain[: t + 1, 4]) < 1e-5
            world = np.concatenate([w @ disp[: t + 1, :2], [0.0]])
            assert np.abs(f[t, k + 1:k + 3] - (rot[t].T @ world)[:2]).max() < 1e-6
            assert abs(f[t, k + 3] - w @ disp[: t + 1, 2]) < 1e-6
            if i < len(HISTORY_FRAMES):  # without the vertical: the same averages, three to a time constant
                j = ROOT_FEATURES + 3 * i
                assert np.abs(default[t, j:j + 3] - f[t, k:k + 3]).max() < 1e-6
    T, rate = 60, 0.2
    rot = np.zeros((T, 2, 3))
    rot[:, 0, 2] = rate * np.arange(T)
    steady = motion_features(Motion(rot, np.tile([0.0, 0.0, 0.9], (T, 1)), rig="test"), history)["root"]
    a = np.exp(-1 / history.frames[-1])
    assert np.allclose(steady[:, -4], rate * (1 - a ** np.arange(T)), atol=1e-6)  # frame 0 turns by nothing
    assert np.allclose(steady[:, -1], 0.0)  # no rise or fall


@pytest.mark.parametrize("bad", [(0.5,), (6.0, float("nan")), (-6.0,), (float("inf"),)])
def test_history_time_constants_below_a_frame_or_not_finite_are_refused(bad):
    assert check_history([6, 15]) == (6.0, 15.0) == MotionHistory([6, 15]).frames
    with pytest.raises(InputError, match="at least 1 frame"):
        MotionHistory(bad)
    with pytest.raises(InputError, match="at least one time constant"):
        MotionHistory(())


def test_heading_of_a_turn_in_place_and_its_rate():
    T = 30
    yaw = np.linspace(0, 3 * np.pi, T)  # 1.5 turns
    rot = np.zeros((T, 2, 3))
    rot[:, 0, 2] = yaw
    m = Motion(rot, np.tile([0.0, 0.0, 0.9], (T, 1)), rig="test")
    f = motion_features(m)["root"]
    assert np.allclose(f[1:, 4], yaw[1] - yaw[0], atol=1e-6)  # heading change per frame, unwrapped correctly
    assert f[0, 4] == 0 and np.allclose(f[:, 1:4], 0, atol=1e-7) and np.allclose(f[:, 0], 0.9)


@pytest.mark.parametrize("history", HISTORIES)
def test_stream_equals_batch(history):
    m = random_motion(seed=3)
    batch = motion_features(m, history)
    rot, origin = heading_frames(m)
    stream = FeatureStream(history)
    for t in range(m.num_frames):
        root, joints, (r, o) = stream.step(m.rotations[t], m.translation[t])
        assert np.abs(root - batch["root"][t]).max() < 1e-5
        assert np.abs(joints - batch["joints"][t]).max() < 1e-5
        assert np.abs(r - rot[t]).max() < 1e-9 and np.abs(o - origin[t]).max() < 1e-9
    with pytest.raises(InputError, match="NaN"):
        stream.step(np.full_like(m.rotations[0], np.nan), m.translation[0])
