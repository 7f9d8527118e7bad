"""BVH parser, writer and forward kinematics."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.geometry.lbs import forward_kinematics
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion.bvh import BvhData, read_bvh, skeleton_to_bvh, write_bvh

SIMPLE = """HIERARCHY
ROOT hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT arm
  {
    OFFSET 10 0 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 5 0 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 0 0 0 0 0 0 0 0
1 2 3 90 0 0 0 0 90
"""


def _anny_bvh(body, T=6, seed=0, **kw) -> tuple[BvhData, np.ndarray]:
    """The Anny skeleton as BVH posed by random rotations; returns it and the reference world
    joint positions ``(T, J, 3)`` in metres from loosefit's own forward kinematics."""
    rng = np.random.default_rng(seed)
    rot = rng.normal(0, 0.6, (T, body.num_joints, 3))
    root = body.rest_root_position()[None] + rng.normal(0, 0.2, (T, 3))
    R = axis_angle_to_matrix(torch.from_numpy(rot))
    rest = torch.from_numpy(body.rest_joints().astype(np.float64))
    world = forward_kinematics(R, torch.from_numpy(root), rest, body.parents)
    bvh = skeleton_to_bvh(body.joint_names, body.parents, body.rest_joints(), R.numpy(), root, 30.0, **kw)
    return bvh, world[..., :3, 3].numpy()


def test_simple_file_closed_form(tmp_path):
    path = tmp_path / "simple.bvh"
    path.write_text(SIMPLE)
    bvh = read_bvh(path)
    assert bvh.names == ["hips", "arm", "arm/End Site"]
    assert bvh.parents.tolist() == [-1, 0, 1]
    assert bvh.fps == 30.0  # 1 / 0.0333333 snapped
    pos, _ = bvh.world()
    assert np.allclose(pos[0], [[0, 0, 0], [10, 0, 0], [15, 0, 0]])
    # Frame 1: root at (1, 2, 3) turned 90 deg about Z (arm along +Y); arm turned 90 deg about its X
    # (along the bone: the end site stays on the bone's line).
    assert np.allclose(pos[1], [[1, 2, 3], [1, 12, 3], [1, 17, 3]], atol=1e-9)


def test_intrinsic_channel_order(tmp_path):
    """``Zrotation Yrotation Xrotation`` is R = Rz @ Ry @ Rx: a child offset along X, rotated
    by (z=90, y=90): Ry turns X to -Z, Rz keeps -Z -> end at (0, 0, -1)."""
    text = SIMPLE.replace("0 0 0 0 0 0 0 0 0\n1 2 3 90 0 0 0 0 90", "0 0 0 90 0 0 0 0 0\n0 0 0 0 0 0 90 90 0")
    path = tmp_path / "order.bvh"
    path.write_text(text)
    pos, _ = read_bvh(path).world()
    # Frame 1: root identity, arm rotated by Rz(90) Ry(90): its end-site offset (5, 0, 0) -> (0, 0, -5).
    assert np.allclose(pos[1, 2] - pos[1, 1], [0, 0, -5], atol=1e-9)
    # Frame 0: the root's own Zrotation of 90 turns the arm's offset (10, 0, 0) to (0, 10, 0).
    assert np.allclose(pos[0, 1], [0, 10, 0], atol=1e-9)


@pytest.mark.parametrize("order,up,scale", [("ZYX", "z", 1.0), ("XZY", "y", 100.0), ("YXZ", "y", 2.54)])
def test_write_read_matches_rig_forward_kinematics(body, tmp_path, order, up, scale):
    """BVH written from loosefit local rotations, read back: FK equals loosefit's FK (up to axes/units)."""
    bvh, reference = _anny_bvh(body, order=order, up=up, scale=scale)
    write_bvh(tmp_path / "a.bvh", bvh)
    back = read_bvh(tmp_path / "a.bvh")
    assert back.num_frames == bvh.num_frames and back.position_mode == "absolute"
    assert sorted(back.names) == sorted(bvh.names)
    pos, _ = back.world()
    A = np.eye(3) if up == "z" else np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    joints = [back.names.index(n) for n in body.joint_names]
    # 6 decimals of degrees: ~2e-8 rad per joint, far below 1e-5 m over a 2 m skeleton.
    assert np.abs(pos[:, joints] / scale @ A - reference).max() < 1e-5


def test_relative_position_channels(body, tmp_path):
    """Root channels stored relative to OFFSET (some converters) read to the same positions."""
    bvh, reference = _anny_bvh(body, up="y", scale=100.0)
    bvh.frames[:, :3] -= bvh.offsets[0]
    write_bvh(tmp_path / "rel.bvh", bvh)
    back = read_bvh(tmp_path / "rel.bvh")
    assert back.position_mode == "relative"
    pos, _ = back.world()
    A = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    assert np.abs(pos[:, [back.names.index(n) for n in body.joint_names]] / 100 @ A - reference).max() < 1e-5


@pytest.mark.parametrize(
    "old,new,message",
    [
        ("CHANNELS 3 Zrotation Yrotation", "CHANNELS 2 Zrotation Yrotation", "declares 2 channels but lists more"),
        ("CHANNELS 3 Zrotation Yrotation Xrotation", "CHANNELS 4 Zrotation Yrotation Xrotation", "is not a channel name"),
        ("Zrotation Yrotation Xrotation\n    End", "Zrotation Yrotation Wrotation\n    End", "is not a channel name"),
        ("CHANNELS 3 Zrotation", "CHANNELS 7 Zrotation", "channel count must be 0..6"),
        ("OFFSET 10 0 0", "OFFSET 10 zero 0", "expected a number"),
        ("1 2 3 90 0 0 0 0 90\n", "", "truncated motion: Frames: 2 but only 1 frame lines"),
        ("1 2 3 90 0 0 0 0 90", "1 2 3 90 0 0 0 0", "line 20: frame has 8 values"),
        ("1 2 3 90 0 0 0 0 90", "1 2 3 90 0 0 0 0 ninety", "line 20: frame value 'ninety' is not a number"),
        ("Frame Time: 0.0333333", "Frame Time: 0", "Frame Time must be positive"),
        ("MOTION", "MOTIONS", "no MOTION section"),
        ("  }\n}\nMOTION", "  }\nMOTION", "unexpected end of file"),
    ],
)
def test_malformed_files_name_file_and_problem(tmp_path, old, new, message):
    path = tmp_path / "bad.bvh"
    assert old in SIMPLE
    path.write_text(SIMPLE.replace(old, new, 1))
    with pytest.raises(InputError) as err:
        read_bvh(path)
    assert message in str(err.value) and str(path) in str(err.value)


def test_error_names_the_line(tmp_path):
    path = tmp_path / "bad.bvh"
    path.write_text(SIMPLE.replace("JOINT arm", "JIONT arm"))
    with pytest.raises(InputError, match=r"line 6: expected JOINT, End Site or '}' in joint 'hips', got 'JIONT'"):
        read_bvh(path)
