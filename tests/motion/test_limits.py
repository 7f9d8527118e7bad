"""Joint limits: swing-twist parameters, sign conventions checked by posing the body, clamping."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.geometry.lbs import forward_kinematics
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion.limits import JointLimits, check_motion, clamp_motion, from_swing_twist, joint_limits, swing_twist
from loosefit.motion.motion import Motion


def _joints(body, rotations: np.ndarray) -> np.ndarray:
    """``(T, J, 3)`` world joint positions of the body at rest translation with local rotations ``(T, J, 3)``."""
    R = axis_angle_to_matrix(torch.from_numpy(np.asarray(rotations, dtype=np.float64)))
    T = R.shape[0]
    trans = torch.from_numpy(np.repeat(body.rest_root_position()[None].astype(np.float64), T, 0))
    world = forward_kinematics(R, trans, torch.from_numpy(body.rest_joints().astype(np.float64)), body.parents)
    return world[..., :3, 3].numpy()


def _pose(body, limits, **joint_params) -> np.ndarray:
    """Joint positions ``(J, 3)`` for anatomical parameters given in degrees per joint name."""
    params = np.zeros((1, len(body.joint_names), 3))
    for name, value in joint_params.items():
        params[0, body.joint_names.index(name)] = np.radians(value)
    return _joints(body, limits.from_anatomical(params))[0]


def _motion(body, rotations) -> Motion:
    rotations = np.asarray(rotations, dtype=np.float32)
    trans = np.repeat(body.rest_root_position()[None], len(rotations), 0)
    return Motion(rotations, trans, 30.0, body.rig, body.joint_names, "test")


def test_swing_twist_closed_forms():
    # A pure rotation about z is all twist, a rotation about an axis in the xy-plane all swing.
    assert np.allclose(swing_twist([0.0, 0.0, 0.7]), [0.0, 0.0, 0.7], atol=1e-9)
    assert np.allclose(swing_twist([0.3, -0.5, 0.0]), [0.3, -0.5, 0.0], atol=1e-9)
    # from_swing_twist composes swing after twist: compare with the matrix product.
    params = np.array([0.4, -0.2, 0.9])
    expected = (axis_angle_to_matrix(torch.tensor([0.4, -0.2, 0.0], dtype=torch.float64))
                @ axis_angle_to_matrix(torch.tensor([0.0, 0.0, 0.9], dtype=torch.float64)))
    got = axis_angle_to_matrix(torch.from_numpy(from_swing_twist(params)))
    assert torch.allclose(got, expected, atol=1e-9)


def test_anatomical_round_trip(body):
    limits = joint_limits(body)
    rng = np.random.default_rng(0)
    params = limits.clamp_anatomical(rng.uniform(limits.lo, limits.hi, size=(64,) + limits.lo.shape))
    params[:, 0] = rng.normal(size=(64, 3))  # the free root keeps its axis-angle
    back = limits.to_anatomical(limits.from_anatomical(params))
    assert np.abs(back - params).max() < 1e-9


def test_arm_frames_follow_the_a_pose(body):
    limits = joint_limits(body)
    rest = body.rest_joints()
    ix = body.joint_names.index
    upper = rest[ix("LeftForeArm")] - rest[ix("LeftArm")]
    frame = limits.frames[ix("LeftArm")]
    assert np.allclose(frame.T @ frame, np.eye(3), atol=1e-9) and np.linalg.det(frame) > 0
    assert np.allclose(frame[:, 2], upper / np.linalg.norm(upper), atol=1e-6)  # z along the bone


def test_signs_by_posing(body):
    """The documented sign conventions, checked on posed joint positions."""
    limits = joint_limits(body)
    ix = body.joint_names.index
    rest = _pose(body, limits)
    for side, out in (("Left", 1.0), ("Right", -1.0)):
        knee = _pose(body, limits, **{f"{side}Leg": (60, 0, 0)})
        assert knee[ix(f"{side}Foot"), 1] - rest[ix(f"{side}Foot"), 1] > 0.2  # foot goes backward
        hip = _pose(body, limits, **{f"{side}UpLeg": (-60, 0, 0)})
        assert hip[ix(f"{side}Foot"), 1] - rest[ix(f"{side}Foot"), 1] < -0.4  # hip flexion: foot forward
        abduct = _pose(body, limits, **{f"{side}UpLeg": (0, -30, 0)})
        assert out * (abduct[ix(f"{side}Foot"), 0] - rest[ix(f"{side}Foot"), 0]) > 0.3  # outward
        toes_up = _pose(body, limits, **{f"{side}Foot": (-20, 0, 0)})
        assert toes_up[ix(f"{side}ToeBase"), 2] > rest[ix(f"{side}ToeBase"), 2] + 0.03
        raise_side = _pose(body, limits, **{f"{side}Arm": (0, -90, 0)})
        assert raise_side[ix(f"{side}Hand"), 2] > rest[ix(f"{side}Arm"), 2] + 0.2  # arm above the shoulder
        forward = _pose(body, limits, **{f"{side}Arm": (80, 0, 0)})
        assert forward[ix(f"{side}Hand"), 1] < rest[ix(f"{side}Hand"), 1] - 0.2
        bend = _pose(body, limits, **{f"{side}ForeArm": (60, 0, 0)})
        shoulder = rest[ix(f"{side}Arm")]
        reach = np.linalg.norm(rest[ix(f"{side}Hand")] - shoulder)
        assert np.linalg.norm(bend[ix(f"{side}Hand")] - shoulder) < reach - 0.1
    lean = _pose(body, limits, Spine=(30, 0, 0))
    assert lean[ix("Head"), 1] < rest[ix("Head"), 1] - 0.1
    side_bend = _pose(body, limits, Spine=(0, 20, 0))
    assert side_bend[ix("Head"), 0] > rest[ix("Head"), 0] + 0.05  # + bends to the body's left


def test_mirrored_parameters_give_mirrored_poses(body):
    limits = joint_limits(body)
    names = body.joint_names
    rng = np.random.default_rng(1)
    params = np.zeros((8, len(names), 3))
    for j, name in enumerate(names):
        if name.startswith("Left") or name in ("LHipJoint", "LThumb"):
            mirror = names.index("Right" + name[4:] if name.startswith("Left") else "R" + name[1:])
            params[:, j] = rng.uniform(limits.lo[j], limits.hi[j], size=(8, 3))
            params[:, mirror] = params[:, j]
    joints = _joints(body, limits.from_anatomical(params))
    for j, name in enumerate(names):
        if name.startswith("Left"):
            mirror = names.index("Right" + name[4:])
            assert np.abs(joints[:, mirror] - joints[:, j] * [-1, 1, 1]).max() < 1e-5


def test_clamp_projects_into_limits(body):
    limits = joint_limits(body)
    rng = np.random.default_rng(2)
    motion = _motion(body, rng.normal(scale=1.2, size=(20, len(body.joint_names), 3)))
    assert limits.violation(motion).max() > 0.5
    clamped = clamp_motion(motion, body)
    assert limits.violation(clamped).max() < 1e-5
    assert np.allclose(clamped.rotations[:, 0], motion.rotations[:, 0])  # the root is free
    again = clamp_motion(clamped, body)
    assert np.abs(again.rotations - clamped.rotations).max() < 1e-5
    # Rotations already inside the limits are left alone.
    inside = limits.clamp_anatomical(rng.uniform(limits.lo, limits.hi, size=(5,) + limits.lo.shape))
    kept = limits.clamp(_motion(body, limits.from_anatomical(inside)))
    assert np.abs(limits.to_anatomical(kept.rotations)[:, 1:] - inside[:, 1:]).max() < 1e-5


def test_backward_knee_is_a_violation(body):
    limits = joint_limits(body)
    knee = body.joint_names.index("LeftLeg")
    rot = np.zeros((3, len(body.joint_names), 3))
    rot[1, knee] = [-0.6, 0.0, 0.0]  # the foot swings forward: hyperextension
    rot[2, 0] = [0.0, 0.0, 3.0]  # a large root rotation is allowed
    motion = _motion(body, rot)
    v = limits.violation(motion)
    assert v[1, knee] == pytest.approx(0.6 - np.radians(10), abs=1e-5)
    assert v[0].max() == 0 and v[2].max() == 0
    with pytest.raises(InputError, match="LeftLeg"):
        check_motion(motion, body)
    check_motion(_motion(body, rot[[0, 2]]), body)


def test_wrong_rig_is_rejected(body):
    class OtherBody:
        rig, name, joint_names = "smpl", "smpl-test", body.joint_names

    with pytest.raises(InputError, match="cmu_mb"):
        JointLimits(OtherBody())
    motion = _motion(body, np.zeros((2, len(body.joint_names), 3)))
    motion.rig = "smpl"
    with pytest.raises(InputError, match="rig"):
        joint_limits(body).violation(motion)
