"""AMASS motion files (SMPL-H ``.npz``): import onto a body rig and export from a loosefit Motion.

An AMASS file holds ``poses (T, 156)``: axis-angle local rotations of the 52 SMPL-H joints (22 body
joints, then 15 per hand) in SMPL's convention (the same as loosefit's: world-aligned joint frames
at rest), ``trans (T, 3)``, ``mocap_framerate``, and optionally ``betas`` and ``gender``. SMPL's rest
pose is a T-pose, Y up, facing +Z; AMASS worlds are Z up, so the root rotation also turns the body
upright. SMPL adds ``trans`` to the *unrotated* rest pelvis: the pelvis is at ``trans + J_pelvis``.

Files from other sources differ: poses stored as ``(T, 52, 3)``, no frame rate (give it as
``source_fps``), a Y-up world (detected from the head-over-pelvis direction), or a ``trans`` that
is only an offset with no floor in mind (the pelvis near the origin, the feet a metre below it).
The floor is where the source's feet touch it: when the lowest foot joint (ankles, toes) at
contact is not within :data:`FLOOR_TOLERANCE` of its standing height above the file's ``z = 0``,
the body is lowered or raised so it is, and the imported motion's feet are checked against the floor
(:func:`~loosefit.motion.retarget.check_feet_on_floor`).

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
from loosefit.io.npz import load_npz
from loosefit.geometry.lbs import forward_kinematics
from loosefit.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from loosefit.geometry.vectors import unit
from loosefit.motion.motion import DEFAULT_FPS, Motion
from loosefit.motion.joint_map import builtin_joint_maps, resolve_joint_map
from loosefit.motion.jumps import drop_far_first_frame
from loosefit.motion.retarget import SourceAnimation, check_feet_on_floor, retarget, to_motion
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
#: How far (metres) the source's foot joints at contact may be from the file's floor ``z = 0`` before
#: the floor is taken from the feet instead (foot joints sit a few centimetres above the soles).
FLOOR_TOLERANCE = 0.1
_FEET = [SMPLH_NAMES.index(n) for n in ("left_ankle", "left_foot", "right_ankle", "right_foot")]


def smplh_rig() -> TargetRig:
    """The SMPL-H skeleton as a retargeting rig (rest frame Y up)."""
    return TargetRig("smplh", list(SMPLH_NAMES), SMPLH_PARENTS, SMPLH_REST.astype(np.float64))


def import_amass(path: str | Path, body, fps: float = DEFAULT_FPS, source_fps: float | None = None,
                 keep_first_frame: bool = False) -> Motion:
    """Read an AMASS ``.npz`` and retarget it onto ``body``'s rig, standing on the floor ``z = 0``.

    Args:
        path: ``.npz`` with ``poses (T, 156)`` or ``(T, 52, 3)`` (or SMPL-X 165 / SMPL 72 / 66 wide),
            ``trans (T, 3)`` and ``mocap_framerate`` (or ``mocap_frame_rate``).
        body: a :class:`~loosefit.body.BodyModel`.
        fps: output frame rate (slerp resampling).
        source_fps: the file's frame rate, for files that store none; when the file has one, the
            two must agree.
        keep_first_frame: keep frame 0 even when the root jumps from it to frame 1 faster than a person
            moves (:func:`~loosefit.motion.jumps.far_first_frame`); by default such a frame is dropped
            before the floor and the calibration are computed, and a warning names the file.

    Returns:
        A :class:`Motion` on ``body.rig`` named after the file.

    Raises:
        InputError: naming the file: missing or malformed arrays, no frame rate and no
            ``source_fps`` (or one that disagrees with the file's), feet that do not meet the floor.
    """
    path = Path(path)
    poses, trans, rate = _read(path, source_fps)
    # The pelvis is at trans + its rest position whatever the rotations: trans is the root's path, in metres.
    if drop_far_first_frame(trans[:2], rate, path, keep_first_frame):
        poses, trans = poses[1:], trans[1:]
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
    A = _world_axes(world[..., :3, 3])
    positions = world[..., :3, 3] @ A.T
    target = TargetRig.from_body(body)
    feet = [target.joint_names.index(n) for n in target.roles.feet]
    positions[..., 2] -= source_floor(positions, float(np.min(target.rest[feet] @ np.asarray(target.roles.up))))
    source = SourceAnimation(
        joint_names=list(SMPLH_NAMES),
        parents=SMPLH_PARENTS,
        positions=positions,
        rotations=A @ world[..., :3, :3],
        fps=rate,
        rest_positions=SMPLH_REST @ _Y_UP_TO_Z_UP.T,
        rest_rotations=np.broadcast_to(_Y_UP_TO_Z_UP, (len(SMPLH_NAMES), 3, 3)),
    )
    resolved = resolve_joint_map(list(SMPLH_NAMES), SMPLH_PARENTS, target, builtin_joint_maps()["smplh"], path)
    local_t, root = retarget(source, target, resolved, calibration="rest", path=path)
    check_feet_on_floor(local_t, root, target, path)
    return to_motion(local_t, root, rate, target, path.stem, fps)


def _world_axes(positions: np.ndarray) -> np.ndarray:
    """``A (3, 3)`` taking the file's world to Z up: the identity for AMASS (Z up), the +90 degree turn
    about X when the head stands over the pelvis along +Y (SMPL's own frame); ``positions (T, 52, 3)``."""
    rise = unit(positions[:, SMPLH_NAMES.index("head")] - positions[:, 0]).mean(0)
    return _Y_UP_TO_Z_UP if rise[1] > max(rise[2], 0.5) else np.eye(3)


def source_floor(positions: np.ndarray, standing: float) -> float:
    """The floor height (metres) of SMPL-H world positions ``(T, 52, 3)``, Z up: ``0`` (the file's own
    floor) when the lowest foot joint at contact (5th percentile over frames) is within
    :data:`FLOOR_TOLERANCE` of ``standing`` (the height of the body's lowest foot joint when it stands
    on the floor), else the height that puts it there."""
    contact = float(np.percentile(positions[:, _FEET, 2].min(1), 5))
    return 0.0 if abs(contact - standing) <= FLOOR_TOLERANCE else contact - standing


def _read(path: Path, source_fps: float | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """``poses (T, W)`` float64, ``trans (T, 3)`` float64 and the frame rate of an AMASS file
    (``source_fps`` when the file has none)."""
    # Only the arrays used: AMASS files may carry others (gender...); damage of any kind names the file.
    z = load_npz(path, "AMASS file", names=("poses", "trans", "mocap_framerate", "mocap_frame_rate"))
    rate_key = next((k for k in ("mocap_framerate", "mocap_frame_rate") if k in z), None)
    missing = sorted({"poses", "trans"} - set(z))
    if missing:
        raise InputError(f"not an AMASS motion, missing arrays {missing}", path)
    try:
        poses = np.asarray(z["poses"], np.float64)
        trans = np.asarray(z["trans"], np.float64)
        rate = float(z[rate_key]) if rate_key else None
    except (TypeError, ValueError) as e:
        raise InputError(f"cannot read AMASS file: {e}", path) from None
    if rate is None:
        if source_fps is None:
            raise InputError("the file stores no frame rate (no mocap_framerate array): give the source's "
                             "frame rate, e.g. `loosefit motion import FILE --fps 30`", path)
        rate = float(source_fps)
    elif source_fps is not None and abs(rate - source_fps) > 1e-6 * rate:
        raise InputError(f"the file's frame rate is {rate:g} fps, --fps says {source_fps:g}", path)
    if poses.ndim == 3 and poses.shape[2] == 3 and poses.shape[1] * 3 in _HAND_START:
        poses = poses.reshape(poses.shape[0], -1)  # (T, 52, 3) -> (T, 156)
    if poses.ndim != 2 or poses.shape[1] not in _HAND_START or poses.shape[0] < 1:
        raise InputError(f"poses must have shape (T, 156) or (T, 52, 3) (SMPL-H; 165, 72 or 66 wide also "
                         f"read), got {poses.shape}", path)
    if trans.shape != (poses.shape[0], 3):
        raise InputError(f"trans must have shape ({poses.shape[0]}, 3), got {trans.shape}", path)
    if not (np.isfinite(poses).all() and np.isfinite(trans).all()):
        raise InputError("poses or trans contain NaN or infinite values", path)
    if not rate > 0:
        raise InputError(f"the frame rate must be positive, got {rate}", path)
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
