"""AMASS (SMPL-H) import and export."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.motion.amass import SMPLH_NAMES, SMPLH_PARENTS, SMPLH_REST, export_amass, import_amass
from tests.motion.test_retarget import smooth_motion


def test_skeleton_table_is_a_t_pose():
    assert len(SMPLH_NAMES) == 52 and SMPLH_PARENTS[0] == -1 and (SMPLH_PARENTS[1:] < np.arange(1, 52)).all()
    at = {n: SMPLH_REST[i] for i, n in enumerate(SMPLH_NAMES)}
    for side, sign in (("left", 1), ("right", -1)):
        leg = at[f"{side}_ankle"] - at[f"{side}_hip"]
        arm = at[f"{side}_wrist"] - at[f"{side}_shoulder"]
        assert leg[1] / np.linalg.norm(leg) < -0.98  # legs straight down (-Y)
        assert sign * arm[0] / np.linalg.norm(arm) > 0.99  # arms horizontal along +-X
        assert sign * at[f"{side}_index1"][0] > sign * at[f"{side}_wrist"][0]


def test_round_trip_keeps_joint_positions(body, tmp_path):
    """Motion -> AMASS -> Motion: bone directions are matched both ways and the root is scaled by
    the leg-length ratio and back, so joints agree to float32 precision. Joints SMPL-H lacks
    (hip sockets, Neck1) stay at rest in the test motion."""
    motion = smooth_motion(body, 30.0, seconds=1.5, seed=3)
    export_amass(tmp_path / "m.npz", motion, body)
    with np.load(tmp_path / "m.npz") as z:
        assert z["poses"].shape == (motion.num_frames, 156) and z["trans"].shape == (motion.num_frames, 3)
        assert float(z["mocap_framerate"]) == 30.0 and str(z["gender"]) == "neutral"
    back = import_amass(tmp_path / "m.npz", body)
    assert back.num_frames == motion.num_frames and back.rig == body.rig and back.name == "m"
    assert np.abs(body.pose(back).joints - body.pose(motion).joints).max() < 1e-4


def test_zero_pose_is_a_t_pose_on_the_a_pose_body(body, tmp_path):
    """SMPL's zero pose turned upright (+90 deg about X) stands facing -Y with the arms out
    horizontally: the A-pose body must put its arms there too, legs straight down."""
    T = 4
    poses = np.zeros((T, 156))
    poses[:, 0] = np.pi / 2
    np.savez(tmp_path / "z.npz", poses=poses, trans=np.tile([0.0, 0.0, 0.95], (T, 1)), mocap_framerate=30.0)
    motion = import_amass(tmp_path / "z.npz", body)
    j = body.pose(motion).joints[0]
    at = lambda n: j[body.joint_names.index(n)]  # noqa: E731
    for side, sign in (("Left", 1), ("Right", -1)):
        upper = at(f"{side}ForeArm") - at(f"{side}Arm")
        assert sign * upper[0] / np.linalg.norm(upper) > np.cos(np.radians(10))
        thigh = at(f"{side}Leg") - at(f"{side}UpLeg")
        assert -thigh[2] / np.linalg.norm(thigh) > np.cos(np.radians(10))
    hips = at("LeftUpLeg") - at("RightUpLeg")
    assert hips[0] / np.linalg.norm(hips) > 0.99  # body left is +X: facing -Y


def test_frame_rate_is_resampled(body, tmp_path):
    motion = smooth_motion(body, 120.0, seconds=0.5)
    export_amass(tmp_path / "fast.npz", motion, body)
    back = import_amass(tmp_path / "fast.npz", body)
    reference = smooth_motion(body, 30.0, seconds=0.5)
    assert back.fps == 30.0 and back.num_frames == reference.num_frames == 16
    assert np.abs(body.pose(back).joints - body.pose(reference).joints).max() < 1e-4


@pytest.mark.parametrize(
    "arrays,message",
    [
        ({"trans": np.zeros((3, 3)), "mocap_framerate": 30.0}, "missing arrays ['poses']"),
        ({"poses": np.zeros((3, 156)), "trans": np.zeros((3, 3))}, "no frame rate"),
        ({"poses": np.zeros((3, 100)), "trans": np.zeros((3, 3)), "mocap_framerate": 30.0}, "poses must have shape"),
        ({"poses": np.zeros((3, 156)), "trans": np.zeros((2, 3)), "mocap_framerate": 30.0}, "trans must have shape (3, 3)"),
        ({"poses": np.full((3, 156), np.nan), "trans": np.zeros((3, 3)), "mocap_framerate": 30.0}, "NaN"),
        ({"poses": np.zeros((3, 156)), "trans": np.zeros((3, 3)), "mocap_framerate": 0.0}, "must be positive"),
    ],
)
def test_malformed_files_name_file_and_problem(body, tmp_path, arrays, message):
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(InputError) as err:
        import_amass(path, body)
    assert message in str(err.value) and str(path) in str(err.value)
