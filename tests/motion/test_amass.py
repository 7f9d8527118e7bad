"""AMASS (SMPL-H) import and export."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from loosefit.motion.amass import _Y_UP_TO_Z_UP, SMPLH_NAMES, SMPLH_PARENTS, SMPLH_REST, export_amass, import_amass
from loosefit.motion.procedural import generate
from loosefit.motion.retarget import check_feet_on_floor
from loosefit.motion.rig import TargetRig
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


def _sole_contact(body, motion) -> float:
    """Height (metres) of the body's lowest vertex where the feet touch the floor (5th percentile over frames)."""
    return float(np.percentile(body.pose(motion).verts[..., 2].min(1), 5))


def test_smplh_file_without_frame_rate_stands_on_the_floor(body, tmp_path):
    """A VirtualBones-style SMPL-H file: ``poses (T, 52, 3)``, ``trans`` only an offset (the pelvis starts
    at SMPL's rest pelvis, the feet a metre below the origin), no frame rate. Without ``source_fps`` it
    is refused naming the file; with it, the body stands on the floor (soles within 2 cm of z = 0 at
    contact), in a Z-up world as in a Y-up one, while a file whose feet stand on its floor keeps it."""
    walk = generate("walk", 1.5, 0, body)
    export_amass(tmp_path / "amass.npz", walk, body)
    with np.load(tmp_path / "amass.npz") as z:
        poses, trans = z["poses"], z["trans"]
    T = len(poses)
    offset = trans - trans[0]
    np.savez(tmp_path / "vb.npz", poses=poses.reshape(T, 52, 3), trans=offset)
    with pytest.raises(InputError, match="no frame rate") as err:
        import_amass(tmp_path / "vb.npz", body)
    assert err.value.path == tmp_path / "vb.npz" and "--fps" in str(err.value)
    with pytest.raises(InputError, match="the file's frame rate is 30 fps, --fps says 25"):
        import_amass(tmp_path / "amass.npz", body, source_fps=25)
    assert _sole_contact(body, walk) == pytest.approx(0.0, abs=1e-5)
    kept = import_amass(tmp_path / "amass.npz", body)
    # The file's floor is right: kept (the round trip through SMPL-H bone directions is good to a millimetre).
    assert np.abs(body.pose(kept).joints - body.pose(walk).joints).max() < 2e-3
    z_up = import_amass(tmp_path / "vb.npz", body, source_fps=30)
    assert z_up.fps == 30 and z_up.num_frames == T
    assert abs(_sole_contact(body, z_up)) < 0.02
    # The same file in SMPL's own Y-up world: the root turned back by -90 degrees about X.
    A = _Y_UP_TO_Z_UP
    root = axis_angle_to_matrix(torch.from_numpy(poses[:, :3])).numpy()
    y_poses = poses.copy()
    y_poses[:, :3] = matrix_to_axis_angle(torch.from_numpy(A.T @ root)).numpy()
    y_trans = (offset + SMPLH_REST[0]) @ A - SMPLH_REST[0]  # the pelvis, at trans + J_pelvis, turned with the world
    np.savez(tmp_path / "vb_y.npz", poses=y_poses.reshape(T, 52, 3), trans=y_trans)
    y_up = import_amass(tmp_path / "vb_y.npz", body, source_fps=30)
    assert np.abs(body.pose(y_up).joints - body.pose(z_up).joints).max() < 1e-4


def test_feet_check_names_how_far_off_the_floor(body):
    """The check on imported motions: the body's rest pose stands (error 0), lifted 0.3 m it is refused."""
    target = TargetRig.from_body(body)
    rest = body.rest_motion(3)
    local = axis_angle_to_matrix(torch.from_numpy(rest.rotations.astype(np.float64))).numpy()
    root = rest.translation.astype(np.float64)
    assert abs(check_feet_on_floor(local, root, target)) < 1e-6
    with pytest.raises(InputError, match="0.30 m above the floor"):
        check_feet_on_floor(local, root + [0.0, 0.0, 0.3], target, Path("m.npz"))
