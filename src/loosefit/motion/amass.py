"""AMASS motion files (SMPL-H ``.npz``): import onto a body rig and export from a loosefit Motion.

An AMASS file holds ``poses (T, 156)``: axis-angle local rotations of the 52 SMPL-H joints (22 body
joints, then 15 per hand) in SMPL's convention (the same as loosefit's: world-aligned joint frames
at rest), ``trans (T, 3)``, ``mocap_framerate``, and optionally ``betas`` and ``gender``. SMPL's rest
pose is a T-pose, Y up, facing +Z; AMASS worlds are Z up, so the root rotation also turns the body
upright. SMPL adds ``trans`` to the *unrotated* rest pelvis: the pelvis is at ``trans + J_pelvis``.

Without the SMPL model files the rest skeleton comes from :data:`SMPLH_REST`, approximate SMPL-H
joint positions (legs straight down, arms horizontal along +-X), the same for every body shape:
``betas`` are read but do not change the skeleton, so imported bone lengths are approximate while
bone directions, which is what retargeting uses, are exact. Files with SMPL-X (165) or SMPL
(72 / 66) pose vectors are read too: their 22 body joints are the same; SMPL-X hands are used.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.lbs import forward_kinematics
from loosefit.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from loosefit.motion.motion import DEFAULT_FPS, Motion
from loosefit.motion.joint_map import builtin_joint_maps, resolve_joint_map
from loosefit.motion.retarget import SourceAnimation, retarget, to_motion
from loosefit.motion.rig import TargetRig
from loosefit.paths import atomic_path

_BODY = (
    # name, parent, approximate rest position (metres, Y up, facing +Z, body left +X)
    ("pelvis", -1, (0.000, -0.223, 0.028)),
    ("left_hip", 0, (0.070, -0.314, 0.024)),
    ("right_hip", 0, (-0.070, -0.314, 0.024)),
    ("spine1", 0, (0.000, -0.110, 0.010)),
    ("left_knee", 1, (0.105, -0.700, 0.030)),
    ("right_knee", 2, (-0.105, -0.700, 0.030)),
    ("spine2", 3, (0.000, 0.025, 0.015)),
    ("left_ankle", 4, (0.090, -1.100, -0.010)),
    ("right_ankle", 5, (-0.090, -1.100, -0.010)),
    ("spine3", 6, (0.000, 0.080, 0.025)),
    ("left_foot", 7, (0.115, -1.155, 0.110)),
    ("right_foot", 8, (-0.115, -1.155, 0.110)),
    ("neck", 9, (0.000, 0.290, 0.000)),
    ("left_collar", 9, (0.075, 0.200, 0.010)),
    ("right_collar", 9, (-0.075, 0.200, 0.010)),
    ("head", 12, (0.000, 0.350, 0.050)),
    ("left_shoulder", 13, (0.175, 0.225, -0.010)),
    ("right_shoulder", 14, (-0.175, 0.225, -0.010)),
    ("left_elbow", 16, (0.430, 0.215, -0.030)),
    ("right_elbow", 17, (-0.430, 0.215, -0.030)),
    ("left_wrist", 18, (0.690, 0.220, -0.025)),
    ("right_wrist", 19, (-0.690, 0.220, -0.025)),
)
# Left-hand finger joints relative to the left wrist, in SMPL-H order (each finger: 1, 2, 3).
_FINGERS = (
    ("index", ((0.100, -0.005, 0.030), (0.135, -0.008, 0.033), (0.160, -0.010, 0.035))),
    ("middle", ((0.105, -0.005, 0.007), (0.145, -0.008, 0.005), (0.172, -0.010, 0.004))),
    ("pinky", ((0.080, -0.012, -0.033), (0.105, -0.015, -0.037), (0.122, -0.017, -0.039))),
    ("ring", ((0.095, -0.008, -0.015), (0.130, -0.011, -0.018), (0.155, -0.013, -0.020))),
    ("thumb", ((0.030, -0.015, 0.050), (0.055, -0.020, 0.070), (0.080, -0.023, 0.085))),
)


def _smplh_skeleton() -> tuple[list[str], np.ndarray, np.ndarray]:
    names = [n for n, _, _ in _BODY]
    parents = [p for _, p, _ in _BODY]
    rest = [np.array(x) for _, _, x in _BODY]
    for side, sign, wrist in (("left", 1.0, 20), ("right", -1.0, 21)):
        for finger, joints in _FINGERS:
            for k, offset in enumerate(joints):
                names.append(f"{side}_{finger}{k + 1}")
                parents.append(wrist if k == 0 else len(names) - 2)
                rest.append(rest[wrist] + np.array(offset) * (sign, 1.0, 1.0))
    return names, np.array(parents), np.array(rest)


#: SMPL-H joint names (52), parents ``(52,)`` and approximate rest positions ``(52, 3)`` (Y up, metres).
SMPLH_NAMES, SMPLH_PARENTS, SMPLH_REST = _smplh_skeleton()
# SMPL's rest frame (Y up, facing +Z) -> AMASS / loosefit world (Z up, facing -Y): +90 degrees about X.
_Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
# Where the hand joints start in a pose vector, by its width (SMPL-H, SMPL-X; None: no finger data).
_HAND_START = {156: 66, 165: 75, 72: None, 66: None}


def smplh_rig() -> TargetRig:
    """The SMPL-H skeleton as a retargeting rig (rest frame Y up)."""
    return TargetRig("smplh", list(SMPLH_NAMES), SMPLH_PARENTS, SMPLH_REST.astype(np.float64))


def import_amass(path: str | Path, body, fps: float = DEFAULT_FPS) -> Motion:
    """Read an AMASS ``.npz`` and retarget it onto ``body``'s rig.

    Args:
        path: ``.npz`` with ``poses (T, 156)`` (or SMPL-X 165 / SMPL 72 / 66 wide), ``trans (T, 3)``
            and ``mocap_framerate`` (or ``mocap_frame_rate``).
        body: a :class:`~loosefit.body.BodyModel`.
        fps: output frame rate (slerp resampling).

    Returns:
        A :class:`Motion` on ``body.rig`` named after the file.
    """
    path = Path(path)
    poses, trans, rate = _read(path)
    T = poses.shape[0]
    rot = np.zeros((T, len(SMPLH_NAMES), 3))
    rot[:, :22] = poses[:, :66].reshape(T, 22, 3)
    start = _HAND_START[poses.shape[1]]
    if start is not None:
        rot[:, 22:] = poses[:, start : start + 90].reshape(T, 30, 3)
    local = axis_angle_to_matrix(torch.from_numpy(rot))
    rest = torch.from_numpy(SMPLH_REST)
    with torch.no_grad():
        world = forward_kinematics(local, torch.from_numpy(trans) + rest[0], rest, SMPLH_PARENTS).numpy()
    source = SourceAnimation(
        joint_names=list(SMPLH_NAMES),
        parents=SMPLH_PARENTS,
        positions=world[..., :3, 3],
        rotations=world[..., :3, :3],
        fps=rate,
        rest_positions=SMPLH_REST @ _Y_UP_TO_Z_UP.T,
        rest_rotations=np.broadcast_to(_Y_UP_TO_Z_UP, (len(SMPLH_NAMES), 3, 3)),
    )
    target = TargetRig.from_body(body)
    resolved = resolve_joint_map(list(SMPLH_NAMES), SMPLH_PARENTS, target, builtin_joint_maps()["smplh"], path)
    local_t, root = retarget(source, target, resolved, calibration="rest", path=path)
    return to_motion(local_t, root, rate, target, path.stem, fps)


def _read(path: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """``poses (T, W)`` float64, ``trans (T, 3)`` float64 and the frame rate of an AMASS file."""
    try:
        with np.load(path, allow_pickle=False) as z:
            files = set(z.files)
            rate_key = next((k for k in ("mocap_framerate", "mocap_frame_rate") if k in files), None)
            missing = sorted({"poses", "trans"} - files) + ([] if rate_key else ["mocap_framerate"])
            if missing:
                raise InputError(f"not an AMASS motion, missing arrays {missing}", path)
            poses = np.asarray(z["poses"], np.float64)
            trans = np.asarray(z["trans"], np.float64)
            rate = float(z[rate_key])
    except InputError:
        raise
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read AMASS file: {e}", path) from None
    if poses.ndim != 2 or poses.shape[1] not in _HAND_START or poses.shape[0] < 1:
        raise InputError(f"poses must have shape (T, 156) (SMPL-H; 165, 72 or 66 also read), got {poses.shape}", path)
    if trans.shape != (poses.shape[0], 3):
        raise InputError(f"trans must have shape ({poses.shape[0]}, 3), got {trans.shape}", path)
    if not (np.isfinite(poses).all() and np.isfinite(trans).all()):
        raise InputError("poses or trans contain NaN or infinite values", path)
    if not rate > 0:
        raise InputError(f"mocap_framerate must be positive, got {rate}", path)
    return poses, trans, rate


def export_amass(path: str | Path, motion: Motion, body) -> None:
    """Write ``motion`` (on ``body``'s rig) as an AMASS SMPL-H ``.npz``, atomically.

    The motion is retargeted onto :data:`SMPLH_REST` by bone directions; body joints without an
    SMPL-H counterpart (``LHipJoint``, ``RHipJoint``, ``Neck1`` on cmu_mb) are folded into their
    parents, finger joints without one stay at rest. Writes ``poses (T, 156)``, ``trans (T, 3)``,
    ``mocap_framerate``, ``betas (16,)`` zeros and ``gender`` ``"neutral"``.
    """
    body.check_motion(motion)
    rest = torch.from_numpy(body.rest_joints().astype(np.float64))
    with torch.no_grad():
        world = forward_kinematics(
            axis_angle_to_matrix(torch.from_numpy(motion.rotations.astype(np.float64))),
            torch.from_numpy(motion.translation.astype(np.float64)),
            rest,
            body.parents,
        ).numpy()
    source = SourceAnimation(
        joint_names=list(body.joint_names),
        parents=np.asarray(body.parents),
        positions=world[..., :3, 3],
        rotations=world[..., :3, :3],
        fps=motion.fps,
        rest_positions=rest.numpy(),
        rest_rotations=np.broadcast_to(np.eye(3), (body.num_joints, 3, 3)),
    )
    target = smplh_rig()
    inverse = builtin_joint_maps()["smplh"].inverted(f"{body.rig}-to-smplh", "smplh")
    resolved = resolve_joint_map(list(body.joint_names), body.parents, target, inverse)
    local, root = retarget(source, target, resolved, calibration="rest")
    poses = matrix_to_axis_angle(torch.from_numpy(local)).numpy().reshape(motion.num_frames, -1)
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez(
            tmp,
            poses=poses,
            trans=root - SMPLH_REST[0],
            mocap_framerate=np.float64(motion.fps),
            betas=np.zeros(16),
            gender=np.str_("neutral"),
        )
