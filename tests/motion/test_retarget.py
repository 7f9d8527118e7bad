"""Retargeting: BVH files of the Anny skeleton in other conventions import to the source's joint
positions; joint maps fail clearly; real Character Creator clips keep their bone directions."""

from __future__ import annotations

import csv
import logging
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from loosefit.errors import InputError
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion.bvh import import_bvh, read_bvh, retarget_bvh, skeleton_to_bvh, write_bvh
from loosefit.motion.motion import Motion
from loosefit.motion.axes import detect_axes
from loosefit.motion.joint_map import load_joint_map, resolve_joint_map
from loosefit.motion.resample import resample, slow_down
from loosefit.motion.rig import TargetRig
from tests.conftest import TEST_MOCAP

# Joints some skeletons lack (Mixamo: hip sockets, second neck bone; fingers are ignored): the test
# motion keeps them at rest so every convention describes the same pose.
AT_REST = ("LHipJoint", "RHipJoint", "Neck1", "LThumb", "LeftFingerBase", "LeftHandFinger1",
           "RThumb", "RightFingerBase", "RightHandFinger1")
MIXAMO = {
    "LowerBack": "Spine", "Spine": "Spine1", "Spine1": "Spine2",
    "LThumb": "LeftHandThumb1", "LeftFingerBase": "LeftHandIndex1", "LeftHandFinger1": "LeftHandIndex2",
    "RThumb": "RightHandThumb1", "RightFingerBase": "RightHandIndex1", "RightHandFinger1": "RightHandIndex2",
}
Y_UP = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # loosefit Z up -> BVH Y up (front -Y -> +Z)


def smooth_motion(body, fps: float, seconds: float = 1.0, seed: int = 0, yaw: float = 0.0) -> Motion:
    """A smooth analytic motion sampled at ``fps``: every joint (but :data:`AT_REST`) swings
    sinusoidally (0.35 rad, 0.3-1 Hz), the root turns ``yaw`` plus a sway and walks."""
    rng = np.random.default_rng(seed)
    J = body.num_joints
    amp = rng.uniform(-0.35, 0.35, (J, 3))
    freq = rng.uniform(0.3, 1.0, (J, 3))
    phase = rng.uniform(0, 2 * np.pi, (J, 3))
    t = np.arange(int(round(seconds * fps)) + 1) / fps
    rot = amp * np.sin(2 * np.pi * freq * t[:, None, None] + phase)
    rot[:, [body.joint_names.index(n) for n in AT_REST]] = 0.0
    rot[:, 0] = [0.2, 0.1, 0.0] * np.sin(2 * np.pi * 0.5 * t[:, None]) + [0.0, 0.0, yaw]
    walk = np.stack([0.3 * t, -0.8 * t, 0.03 * np.sin(2 * np.pi * 2 * t)], 1)
    return Motion(rot, body.rest_root_position() + walk, fps, body.rig, body.joint_names, "smooth")


def to_bvh(body, motion: Motion, names=None, keep=None, rest=None, local=None, **kw):
    """The Anny skeleton (or the joints ``keep``, re-parented to their nearest kept ancestor) as BVH."""
    keep = list(range(body.num_joints)) if keep is None else keep
    rest = body.rest_joints() if rest is None else rest
    local = axis_angle_to_matrix(torch.from_numpy(motion.rotations.astype(np.float64))).numpy() if local is None else local
    parents = []
    for j in keep:
        p = body.parents[j]
        while p >= 0 and p not in keep:
            p = body.parents[p]
        parents.append(-1 if p < 0 else keep.index(p))
    names = [body.joint_names[j] for j in keep] if names is None else names
    return skeleton_to_bvh(names, np.array(parents), rest[keep], local[:, keep], motion.translation, motion.fps, **kw)


def joints(body, motion: Motion) -> np.ndarray:
    """``(T, J, 3)`` posed joint positions, metres."""
    return body.pose(motion).joints


def test_cmu_names_y_up_centimetres_120fps(body, tmp_path):
    """120 fps resamples to 30 fps exactly (every 4th frame); left: float32 and 6-decimal text."""
    write_bvh(tmp_path / "cmu.bvh", to_bvh(body, smooth_motion(body, 120.0), up="y", scale=100.0, order="ZXY"))
    motion = import_bvh(tmp_path / "cmu.bvh", body)
    reference = smooth_motion(body, 30.0)
    assert motion.num_frames == reference.num_frames == 31 and motion.fps == 30.0
    assert motion.joint_names == body.joint_names and motion.name == "cmu"
    assert np.abs(joints(body, motion) - joints(body, reference)).max() < 1e-4


def test_mixamo_names_z_up_metres_30fps(body, tmp_path):
    motion = smooth_motion(body, 30.0)
    keep = [j for j, n in enumerate(body.joint_names) if n not in ("LHipJoint", "RHipJoint", "Neck1")]
    names = ["mixamorig:" + MIXAMO.get(body.joint_names[j], body.joint_names[j]) for j in keep]
    write_bvh(tmp_path / "mixamo.bvh", to_bvh(body, motion, names=names, keep=keep, order="XYZ"))
    imported = import_bvh(tmp_path / "mixamo.bvh", body)
    assert imported.num_frames == motion.num_frames
    assert np.abs(joints(body, imported) - joints(body, motion)).max() < 1e-4


def _custom(body, tmp_path, fps=50.0, ignore=True, **overrides) -> tuple[Path, Path]:
    """A custom-named skeleton with an extra ``prop`` joint in the left hand, and its YAML map."""
    motion = smooth_motion(body, fps)
    names = [f"b{j:02d}_{n.lower()}" for j, n in enumerate(body.joint_names)] + ["prop"]
    hand = body.joint_names.index("LeftHand")
    rest = np.concatenate([body.rest_joints(), body.rest_joints()[hand : hand + 1] + [0.0, 0.0, -0.1]])
    local = axis_angle_to_matrix(torch.from_numpy(motion.rotations.astype(np.float64))).numpy()
    local = np.concatenate([local, local[:, :1]], 1)  # the prop spins like the root
    bvh = skeleton_to_bvh(names, np.append(body.parents, hand), rest, local, motion.translation, fps, up="y")
    write_bvh(tmp_path / "custom.bvh", bvh)
    data = {"name": "custom", "joints": {n: names[j] for j, n in enumerate(body.joint_names)}}
    if ignore:
        data["ignore"] = ["prop"]
    data["joints"].update(overrides)
    (tmp_path / "custom.yaml").write_text(yaml.safe_dump(data))
    return tmp_path / "custom.bvh", tmp_path / "custom.yaml"


def test_custom_skeleton_yaml_map_50fps(body, tmp_path):
    """50 fps -> 30 fps interpolates. Slerp of a rotation whose angle accelerates at most
    a = 0.35 rad * (2 pi * 1 Hz)^2 ~ 14 rad/s^2 errs by <= a h^2 / 8 = 7e-4 rad at h = 1/50 s;
    over chains of up to ~6 joints and 0.8 m of lever that is < 3.5 mm, so 5 mm holds."""
    bvh_path, map_path = _custom(body, tmp_path)
    imported = import_bvh(bvh_path, body, joint_map=map_path)
    reference = smooth_motion(body, 30.0)
    assert imported.num_frames == reference.num_frames
    err = np.abs(joints(body, imported) - joints(body, reference)).max()
    assert 1e-5 < err < 5e-3  # interpolated, not copied


def test_t_pose_source_puts_arms_where_the_source_has_them(body, tmp_path):
    """A T-pose skeleton (arms turned horizontal at the shoulders) posed so its world bones equal
    the A-pose motion's lands on the A-pose body at the source's positions."""
    motion = smooth_motion(body, 30.0)
    rest = body.rest_joints().astype(np.float64).copy()
    world = body.pose(motion).joint_transforms[..., :3, :3].astype(np.float64)
    W_source = world.copy()
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        arm = body.joint_names.index(f"{side}Arm")
        below = [j for j in range(body.num_joints) if _is_below(body.parents, j, arm)]
        d = rest[body.joint_names.index(f"{side}ForeArm")] - rest[arm]
        d /= np.linalg.norm(d)
        # The smallest rotation taking the A-pose upper arm to horizontal (+-X).
        axis = np.cross(d, [sign, 0.0, 0.0])
        angle = np.arctan2(np.linalg.norm(axis), d @ [sign, 0.0, 0.0])
        Q = axis_angle_to_matrix(torch.from_numpy(axis / np.linalg.norm(axis) * angle)).numpy()
        rest[below] = (rest[below] - rest[arm]) @ Q.T + rest[arm]
        W_source[:, below] = world[:, below] @ Q.T
    assert np.allclose(rest[body.joint_names.index("LeftForeArm"), 2], rest[body.joint_names.index("LeftArm"), 2])
    local = W_source.copy()
    local[:, 1:] = np.swapaxes(W_source[:, body.parents[1:]], -1, -2) @ W_source[:, 1:]
    write_bvh(tmp_path / "tpose.bvh", to_bvh(body, motion, rest=rest, local=local, up="y", scale=100.0))
    imported = import_bvh(tmp_path / "tpose.bvh", body)
    assert np.abs(joints(body, imported) - joints(body, motion)).max() < 1e-4


def _is_below(parents, j, ancestor) -> bool:
    while j >= 0:
        if j == ancestor:
            return True
        j = parents[j]
    return False


def test_facing_is_detected(body, tmp_path):
    """A Z-up file whose character faces +X turns by -90 degrees about Z so it faces -Y."""
    motion = smooth_motion(body, 30.0, yaw=np.pi / 2)
    write_bvh(tmp_path / "turned.bvh", to_bvh(body, motion))
    imported = import_bvh(tmp_path / "turned.bvh", body)
    turn = np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]])  # -90 deg about Z
    assert np.abs(joints(body, imported) - joints(body, motion) @ turn.T).max() < 1e-4
    # The same file read with its axes given explicitly (front +Y: no turn) reproduces the source.
    kept = import_bvh(tmp_path / "turned.bvh", body, up="z", front="-y")
    assert np.abs(joints(body, kept) - joints(body, motion)).max() < 1e-4


def test_unknown_joints_are_listed(body, tmp_path):
    bvh_path, map_path = _custom(body, tmp_path, ignore=False)
    with pytest.raises(InputError, match=r"unknown source joints, neither mapped nor ignored: \['prop'\]") as err:
        import_bvh(bvh_path, body, joint_map=map_path)
    assert str(bvh_path) in str(err.value)


def test_missing_joints_are_listed(body, tmp_path):
    bvh_path, map_path = _custom(body, tmp_path, LeftLeg="no_such_knee", Head=["nope", "b18_head"])
    with pytest.raises(InputError) as err:
        import_bvh(bvh_path, body, joint_map=map_path)
    message = str(err.value)
    assert "missing source joints" in message and "LeftLeg <- no_such_knee" in message and str(bvh_path) in message
    assert "Head" not in message  # the second alternative exists
    assert "b03_leftleg" in message  # now unmapped, so unknown


def test_unrecognised_skeleton_without_map(body, tmp_path):
    bvh_path, _ = _custom(body, tmp_path)
    with pytest.raises(InputError, match="does not fit: missing source joints") as err:
        import_bvh(bvh_path, body)
    assert "Hips <- " in str(err.value)


@pytest.mark.parametrize(
    "content,message",
    [
        ("joints: {Hips: a}\nfoo: 1\n", "unknown keys ['foo']"),
        ("joints: []\n", "non-empty 'joints' mapping"),
        ("joints: {Hips: 3}\n", "must name a source joint"),
        ("joints: {Hips: a}\ncalibration: tpose\n", "calibration must be 'rest' or 'motion'"),
        ("joints: {Hips: a}\nup: w\n", "axis must be one of x, y, z"),
        ("joints: {Hips: [a\n", "cannot read joint map"),
    ],
)
def test_bad_joint_map_names_the_yaml(tmp_path, content, message):
    path = tmp_path / "map.yaml"
    path.write_text(content)
    with pytest.raises(InputError) as err:
        load_joint_map(path)
    assert message in str(err.value) and str(path) in str(err.value)


def test_map_with_joints_the_rig_lacks(body, tmp_path):
    bvh_path, map_path = _custom(body, tmp_path, Tail="prop")
    with pytest.raises(InputError, match=r"names joints that rig 'cmu_mb' lacks: \['Tail'\]"):
        import_bvh(bvh_path, body, joint_map=map_path)


def test_resample_is_exact_for_uniform_rotation_and_linear_translation():
    """Slerp reproduces a rotation about a fixed axis at constant speed; lerp a straight line."""
    axis = np.array([1.0, 2.0, 2.0]) / 3
    t_in, t_out = np.arange(25) / 24.0, np.arange(31) / 30.0
    make = lambda t, fps: Motion(  # noqa: E731
        np.stack([(2.5 * t[:, None] * axis), (-1.0 * t[:, None] * axis)], 1), np.outer(t, [1.0, -2.0, 0.5]), fps
    )
    out = resample(make(t_in, 24.0), 30.0)
    expected = make(t_out, 30.0)
    assert out.num_frames == 31 and out.fps == 30.0
    assert np.abs(out.rotations - expected.rotations).max() < 1e-5
    assert np.abs(out.translation - expected.translation).max() < 1e-6


def test_slow_down_keeps_source_frames_and_rate():
    """Every 4th frame of a walk slowed 4x is a frame of the walk; the rate stays, the length grows."""
    t = np.arange(31) / 30.0
    rng = np.random.default_rng(0)
    rotations = rng.normal(size=(31, 3, 3)) * 0.4
    motion = Motion(rotations, np.outer(t, [1.0, 0.0, 0.2]), 30.0)
    slowed = slow_down(motion, 4)
    assert slowed.fps == 30.0 and slowed.num_frames == 30 * 4 + 1
    assert np.abs(slowed.translation[::4] - motion.translation).max() < 1e-9
    same = axis_angle_to_matrix(torch.from_numpy(slowed.rotations[::4])) - axis_angle_to_matrix(torch.from_numpy(rotations))
    assert same.abs().max() < 1e-6
    # in between, a quarter of the way along the source's step
    assert np.allclose(slowed.translation[1], motion.translation[0] + 0.25 * (motion.translation[1] - motion.translation[0]))


def _bones(rig: TargetRig, source_of: dict[int, int]):
    """(target joint, target child, on the main chain) for each pair of mapped joints."""
    bones = []
    for c in source_of:
        j = rig.parents[c]
        while j >= 0 and j not in source_of:
            j = rig.parents[j]
        if j >= 0:
            siblings = [k for k in source_of if k != c and _nearest_mapped(rig.parents, k, source_of) == j]
            main = rig.parents[j] >= 0 and (not siblings or rig.joint_names[c] == "Neck")
            bones.append((j, c, main))
    return bones


def _nearest_mapped(parents, k, source_of):
    p = parents[k]
    while p >= 0 and p not in source_of:
        p = parents[p]
    return p


def _imported_clips(mocap: Path) -> set[str]:
    """The clips ``clips.csv`` marks "Imported": their frame 0 is a T-pose the converter put before the motion."""
    with open(mocap / "clips.csv", newline="") as f:
        return {f"{int(r['Subject']):03d}_{int(r['Trial #']):02d}.bvh" for r in csv.DictReader(f) if r["Status"] == "Imported"}


@pytest.mark.parametrize("clip", sorted(p.name for p in TEST_MOCAP.glob("*.bvh")))
def test_real_character_creator_clips(body, clip, caplog):
    """Real CMU clips on the 99-joint CC skeleton (their first second, as the tests keep them). Chain bones (thigh, shin, foot,
    spine, neck, clavicle, upper arm, forearm) point exactly where the source's do (< 0.5 deg).
    Bones from the pelvis and the branch bones to the clavicles join points the two skeletons place
    differently (CC's clavicles start 21 cm above its upper spine joint, Anny's 10 cm): those keep
    the constant offset of the skeletons' shapes, so their angle to the source's varies < 1 deg.
    The T-pose put before the motion in the "Imported" clips is dropped, and no frame of the others."""
    bvh = read_bvh(TEST_MOCAP / clip)
    with caplog.at_level(logging.WARNING, logger="loosefit.motion"):
        motion = retarget_bvh(bvh, body)
    dropped = [r.getMessage() for r in caplog.records if "frame 0 is" in r.getMessage()]
    assert bool(dropped) == (clip in _imported_clips(TEST_MOCAP)), dropped
    if dropped:
        bvh = bvh.select(slice(1, None))
    assert bvh.fps == 60.0 and motion.fps == 30.0
    assert motion.num_frames == (bvh.num_frames - 1) // 2 + 1  # every other frame
    rig = TargetRig.from_body(body)
    resolved = resolve_joint_map(bvh.names, bvh.parents, rig, "cc", skip=bvh.is_end_site())
    positions, _ = bvh.world()
    A = detect_axes(positions, resolved, rig)
    assert np.allclose(A @ [0, 1, 0], [0, 0, 1])  # the files are Y up
    source = (positions @ A.T)[::2]
    posed = joints(body, motion).astype(np.float64)
    bones = _bones(rig, resolved.source_of)
    assert len(bones) == 22 and sum(m for *_, m in bones) == 17
    for j, c, main in bones:
        a = posed[:, c] - posed[:, j]
        b = source[:, resolved.source_of[c]] - source[:, resolved.source_of[j]]
        cos = (a * b).sum(-1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1)
        angle = np.degrees(np.arccos(np.clip(cos, -1, 1)))
        name = f"{rig.joint_names[j]}->{rig.joint_names[c]}"
        if main:
            assert angle.max() < 0.5, name
        else:
            assert angle.std() < 1.0, name
    # Neither floating nor sunk: when the feet are down (5th percentile of the lower toe's height;
    # 005_06 starts with a cartwheel) the toes are at their rest height (2.4 cm) within 4 cm, the
    # difference between the skeletons' feet (ankle height, foot length) in ballet's pointed feet.
    toes = [rig.joint_names.index(n) for n in ("LeftToeBase", "RightToeBase")]
    assert abs(np.percentile(posed[:, toes, 2].min(1), 5) - body.rest_joints()[toes, 2].min()) < 0.04



@pytest.mark.parametrize("calibration", ["rest", "motion"])
def test_steeper_feet_stay_on_the_floor(body, tmp_path, calibration):
    """A source whose ankles stand 3 cm higher above its toes (its rest pose raised to stand on the floor)
    walks with its feet planted. Bone directions are copied, so the target's feet tilt as steeply, and the
    scaled root alone left them 2.4 cm under the floor with rest calibration (6 mm above with floor-contact
    calibration), as real mocap skeletons do. Imported, the target's feet meet the floor as the source's
    do: contact (5th percentile of the lowest foot joint) minus rest foot height equals the source's within
    1 mm (the leg ratio scales it) with rest calibration, and is zero with floor-contact calibration."""
    from loosefit.motion.procedural import generate
    from loosefit.motion.retarget import contact_height

    motion = generate("walk", 2.0, 0, body)
    names = body.joint_names
    rest = body.rest_joints().astype(np.float64).copy()
    toes = [names.index("LeftToeBase"), names.index("RightToeBase")]
    toes = [j for j in range(len(names)) if any(j == a or _is_below(body.parents, j, a) for a in toes)]
    rest[toes, 2] -= 0.03
    rest[:, 2] += 0.03
    raised = Motion(motion.rotations, motion.translation + [0.0, 0.0, 0.03], motion.fps, body.rig, names, "walk")
    write_bvh(tmp_path / "long.bvh", to_bvh(body, raised, rest=rest))
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(
        {"name": "long", "joints": {n: n for n in names}, "calibration": calibration}))
    feet = [names.index(n) for n in ("LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase")]
    src = read_bvh(tmp_path / "long.bvh")
    above_s = contact_height(src.world()[0][:, feet, 2]) - src.rest_world()[0][feet, 2].min()
    assert abs(above_s) < 0.01  # the source walks on its floor

    imported = import_bvh(tmp_path / "long.bvh", body, joint_map=tmp_path / "map.yaml")
    above_t = contact_height(joints(body, imported)[:, feet, 2]) - body.rest_joints()[feet, 2].min()
    expected = above_s if calibration == "rest" else 0.0
    assert abs(above_t - expected) < 1e-3 + 0.06 * abs(above_s), (above_t, expected)
