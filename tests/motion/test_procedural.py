"""Procedural motions: shapes, smoothness, joint limits, floor contact, gait structure, flights."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.geometry.lbs import forward_kinematics
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion.limits import joint_limits
from loosefit.motion.procedural import KINDS, generate

SECONDS = 4.0
SEEDS = (0, 1, 2)
GRAVITY = 9.81
#: Bound on the frame-to-frame rotation of any joint, rad/s (fast kicks and take-offs stay under it).
JOINT_RATE = 25.0
#: Bound on the root's rotation rate, rad/s: spins reach 2 turns per second (12.6 rad/s).
ROOT_RATE = {"spin": 25.0, "jump": 25.0, "mix": 25.0}
ROOT_RATE_OTHER = 6.0
FEET = (("LeftFoot", "LeftToeBase"), ("RightFoot", "RightToeBase"))


@pytest.fixture(scope="module")
def motions(body):
    return {(kind, seed): generate(kind, SECONDS, seed, body) for kind in KINDS for seed in SEEDS}


def _joints(body, motion) -> np.ndarray:
    """``(T, J, 3)`` posed joint positions (forward kinematics of the body's rig)."""
    R = axis_angle_to_matrix(torch.from_numpy(motion.rotations.astype(np.float64)))
    world = forward_kinematics(
        R, torch.from_numpy(motion.translation.astype(np.float64)),
        torch.from_numpy(body.rest_joints().astype(np.float64)), body.parents,
    )
    return world[..., :3, 3].numpy()


def _rates(motion) -> np.ndarray:
    """``(T - 1, J)`` true angle of the relative rotation between consecutive frames, times fps."""
    R = axis_angle_to_matrix(torch.from_numpy(motion.rotations.astype(np.float64))).numpy()
    rel = np.einsum("tjba,tjbc->tjac", R[:-1], R[1:])  # R_t^T R_{t+1}
    cos = (np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(cos, -1.0, 1.0)) * motion.fps


def _lowest_foot(body, joints) -> np.ndarray:
    """``(T, 2, 3)`` per foot, the position of its lowest joint (ankle or toes) in each frame."""
    ix = body.joint_names.index
    out = []
    for foot in FEET:
        p = joints[:, [ix(n) for n in foot]]
        out.append(p[np.arange(len(p)), p[:, :, 2].argmin(1)])
    return np.stack(out, 1)


def _heading_frame(motion, vectors) -> np.ndarray:
    """Horizontal ``(T, ..., 2)`` components of world vectors in the pelvis heading frame (x left, y back)."""
    R = axis_angle_to_matrix(torch.from_numpy(motion.rotations[:, 0].astype(np.float64))).numpy()
    fwd = R @ np.array([0.0, -1.0, 0.0])
    yaw = np.arctan2(fwd[:, 0], -fwd[:, 1]).reshape((-1,) + (1,) * (vectors.ndim - 2))
    c, s = np.cos(-yaw), np.sin(-yaw)
    return np.stack([c * vectors[..., 0] - s * vectors[..., 1], s * vectors[..., 0] + c * vectors[..., 1]], -1)


def test_kinds():
    expected = {"walk", "run", "turn", "spin", "jump", "kick", "squat", "bow", "arm_raise", "wave", "sway", "mix"}
    assert set(KINDS) == expected


def test_shapes_names_and_start(body, motions):
    T = int(round(SECONDS * 30))
    for (kind, seed), m in motions.items():
        assert m.rotations.shape == (T, body.num_joints, 3) and m.rotations.dtype == np.float32
        assert m.translation.shape == (T, 3) and m.translation.dtype == np.float32
        assert np.isfinite(m.rotations).all() and np.isfinite(m.translation).all()
        assert m.fps == 30.0 and m.rig == body.rig and m.joint_names == body.joint_names
        assert m.name.startswith(f"{kind}:seed={seed}")
        # Starts above the origin facing -y.
        assert np.abs(m.translation[0, :2]).max() < 1e-5
        fwd = axis_angle_to_matrix(torch.from_numpy(m.rotations[0, 0].astype(np.float64))).numpy() @ [0.0, -1.0, 0.0]
        assert fwd[0] == pytest.approx(0.0, abs=1e-5) and fwd[1] < 0


def test_angular_velocity_bounded(motions):
    for (kind, seed), m in motions.items():
        rate = _rates(m)
        assert rate[:, 0].max() < ROOT_RATE.get(kind, ROOT_RATE_OTHER), (kind, seed, rate[:, 0].max())
        assert rate[:, 1:].max() < JOINT_RATE, (kind, seed, rate[:, 1:].max())
        speed = np.linalg.norm(np.diff(m.translation, axis=0), axis=1) * m.fps
        assert speed.max() < 6.0, (kind, seed)


def test_joint_limits_respected(body, motions):
    limits = joint_limits(body)
    for key, m in motions.items():
        assert limits.violation(m).max() < 1e-3, key


def test_seeds_differ_and_repeat(body, motions):
    for kind in KINDS:
        a, b = motions[(kind, 0)], motions[(kind, 1)]
        assert np.abs(a.rotations - b.rotations).max() > 0.2, kind
    again = generate("sway", SECONDS, 1, body)
    assert np.array_equal(again.rotations, motions[("sway", 1)].rotations)
    assert np.array_equal(again.translation, motions[("sway", 1)].translation)


def test_feet_stay_on_or_above_the_floor(body, motions):
    toe_flat = body.rest_joints()[body.joint_names.index("LeftToeBase"), 2]
    for (kind, seed), m in motions.items():
        low = _lowest_foot(body, _joints(body, m))[..., 2]
        assert low.min() > -0.01, (kind, seed, low.min())
        if kind not in ("run", "jump", "mix"):
            # No hovering: in every frame at least one foot is on the floor.
            assert low.min(1).max() < toe_flat + 0.01, (kind, seed)


@pytest.mark.parametrize("kind", ["walk", "run", "turn"])
def test_planted_feet_do_not_slide(proxy_body, motions, kind):
    """The lowest joint of a foot on the floor barely moves horizontally (measured on body.pose joints)."""
    toe_flat = proxy_body.rest_joints()[proxy_body.joint_names.index("LeftToeBase"), 2]
    for seed in SEEDS:
        m = motions[(kind, seed)]
        low = _lowest_foot(proxy_body, proxy_body.pose(m).joints)
        speed = np.linalg.norm(np.diff(low[..., :2], axis=0), axis=-1) * m.fps  # (T - 1, 2)
        down = (low[:-1, :, 2] < toe_flat + 0.005) & (low[1:, :, 2] < toe_flat + 0.005)
        assert down.mean() > 0.2, (kind, seed)
        root_speed = np.linalg.norm(np.diff(m.translation[:, :2], axis=0), axis=1).mean() * m.fps
        reference = max(root_speed, 0.5)
        assert np.median(speed[down]) < 0.02 * reference, (kind, seed)
        assert speed[down].mean() < 0.1 * reference, (kind, seed, speed[down].mean(), root_speed)


def test_walk_alternates_legs_and_swings_arms(body, motions):
    ix = body.joint_names.index
    for seed in SEEDS:
        m = motions[("walk", seed)]
        joints = _joints(body, m)
        rel = _heading_frame(m, joints - joints[:, :1])[..., 1]  # backward offset from the pelvis
        left, right = rel[:, ix("LeftFoot")], rel[:, ix("RightFoot")]
        assert np.corrcoef(left, right)[0, 1] < -0.7  # alternating legs
        assert np.ptp(left) > 0.4  # a real stride
        assert np.corrcoef(rel[:, ix("LeftHand")], right)[0, 1] > 0.5  # left arm swings with the right leg
        assert np.corrcoef(rel[:, ix("RightHand")], left)[0, 1] > 0.5
        speed = np.linalg.norm(m.translation[-1, :2] - m.translation[0, :2]) / (m.duration - 1 / m.fps)
        assert 0.5 < speed < 1.8
        assert 0.01 < np.ptp(m.translation[:, 2]) < 0.12  # the pelvis bobs


def test_run_and_jump_fly_ballistically(body, motions):
    toe_flat = body.rest_joints()[body.joint_names.index("LeftToeBase"), 2]
    for kind, clearance in (("run", 0.02), ("jump", 0.03)):
        for seed in SEEDS:
            m = motions[(kind, seed)]
            low = _lowest_foot(body, _joints(body, m))[..., 2].min(1)
            air = low > toe_flat + clearance
            assert air.any(), (kind, seed)
            z = m.translation[:, 2].astype(np.float64)
            inside = air[:-2] & air[1:-1] & air[2:]  # second differences within one flight
            accel = (z[2:] - 2 * z[1:-1] + z[:-2]) * m.fps**2
            if kind == "jump":
                assert inside.sum() >= 3
            assert np.abs(accel[inside] + GRAVITY).max(initial=0.0) < 0.2, (kind, seed)


def test_spin_turns_fast_in_place(motions):
    for seed in SEEDS:
        m = motions[("spin", seed)]
        rate = _rates(m)[:, 0]
        assert 2 * np.pi <= rate.max() <= 2.2 * 2 * np.pi  # 1 to 2 turns per second
        assert np.linalg.norm(m.translation[:, :2] - m.translation[:1, :2], axis=1).max() < 0.6


def test_mix_chains_kinds(motions):
    for seed in SEEDS:
        m = motions[("mix", seed)]
        parts = m.name.split(":")[2].split("+")
        assert len(parts) >= 2 and set(parts) <= set(KINDS) - {"mix"}


def test_fps_sets_the_frame_count(body):
    a = generate("walk", 2.0, 3, body, fps=30)
    b = generate("walk", 2.0, 3, body, fps=60)
    assert (a.num_frames, b.num_frames, b.fps) == (60, 120, 60.0)
    speed = lambda m: np.linalg.norm(np.diff(m.translation[:, :2], axis=0), axis=1).mean() * m.fps  # noqa: E731
    assert speed(b) == pytest.approx(speed(a), rel=0.05)


def test_bad_input(body):
    with pytest.raises(InputError, match="unknown procedural motion kind 'moonwalk'"):
        generate("moonwalk", 1.0, 0, body)
    for seconds in (0, -1.0, float("nan")):
        with pytest.raises(InputError, match="seconds"):
            generate("walk", seconds, 0, body)
    with pytest.raises(InputError, match="fps"):
        generate("walk", 1.0, 0, body, fps=0)
    with pytest.raises(InputError, match="seed"):
        generate("walk", 1.0, -3, body)

    class OtherBody:
        rig, name, joint_names = "smpl", "smpl-test", body.joint_names

    with pytest.raises(InputError, match="cmu_mb"):
        generate("walk", 1.0, 0, OtherBody())
