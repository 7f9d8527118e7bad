"""Garments and motions built by hand for the simulator tests (no template or generator needed)."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.garment import Garment
from loosefit.motion.motion import Motion

ARM_JOINTS = ("Shoulder", "Arm", "Hand", "Thumb", "Finger")


def ring_skirt(body, n_around: int = 40, n_down: int = 20, length: float = 0.45, flare: float = 0.35, margin: float = 0.012):
    """A flared tube skirt from the waist (z = 1.0 m) down, ``n_down`` rings of ``n_around`` vertices.

    Each ring hugs the widest non-arm body section at or above its height (plus ``margin``) and
    flares out by ``flare * drop**1.5``; the waist ring is pinned.
    """
    verts = body.rest_verts()
    arm = np.isin(body.skinning_weights().argmax(1), [i for i, n in enumerate(body.joint_names) if any(a in n for a in ARM_JOINTS)])
    torso = verts[~arm]
    centre = np.array([0.0, -0.03])
    angle = np.arctan2(torso[:, 1] - centre[1], torso[:, 0] - centre[0])
    radius = np.hypot(torso[:, 0] - centre[0], torso[:, 1] - centre[1])
    z = np.linspace(1.0, 1.0 - length, n_down)
    theta = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    gap = np.abs((angle[None, :] - theta[:, None] + np.pi) % (2 * np.pi) - np.pi)  # (n_around, N)
    profile = np.zeros((n_down, n_around))
    for i, zi in enumerate(z):
        near = (np.abs(torso[:, 2] - zi) < 0.015)[None, :] & (gap < 2 * np.pi / n_around)
        profile[i] = np.where(near, radius[None, :], 0.0).max(axis=1)
    profile = np.maximum.accumulate(profile, axis=0)  # never narrower than the body above
    r = profile + margin + flare * (1.0 - z)[:, None] ** 1.5
    ring = np.stack([centre[0] + r * np.cos(theta), centre[1] + r * np.sin(theta), np.repeat(z[:, None], n_around, 1)], -1)
    faces = []
    for i in range(n_down - 1):
        for a in range(n_around):
            p, q = i * n_around + a, i * n_around + (a + 1) % n_around
            faces += [(p, q + n_around, q), (p, p + n_around, q + n_around)]
    pinned = np.zeros(n_down * n_around, bool)
    pinned[:n_around] = True
    return Garment(ring.reshape(-1, 3), np.array(faces, np.int64), pinned, kind="skirt", params={"rings": n_down}, name="ring-skirt")


def spin(body, frames: int, turns_per_second: float = 1.0) -> Motion:
    """The body turning about +Z, accelerating over the first half second."""
    t = np.arange(frames) / 30.0
    ramp = np.minimum(t / 0.5, 1.0)
    angle = 2 * np.pi * turns_per_second * np.where(t < 0.5, t * ramp / 2, t - 0.25)
    rot = np.zeros((frames, body.num_joints, 3), np.float32)
    rot[:, 0, 2] = angle
    trans = np.repeat(body.rest_root_position()[None], frames, 0)
    return Motion(rot, trans, 30.0, body.rig, body.joint_names, "spin")


def walk(body, frames: int, stride_angle: float = 0.45, speed: float = 1.1) -> Motion:
    """A crude walk: legs swing about X in opposition (1 Hz steps), knees bend on the back swing,
    the root moves forward (-Y) and bobs."""
    j = body.joint_names.index
    t = np.arange(frames) / 30.0
    phase = 2 * np.pi * t
    ramp = np.minimum(t / 0.3, 1.0)
    swing = stride_angle * np.sin(phase) * ramp
    rot = np.zeros((frames, body.num_joints, 3), np.float32)
    rot[:, j("LeftUpLeg"), 0] = -swing  # negative about X lifts the leg forward (-Y)
    rot[:, j("RightUpLeg"), 0] = swing
    rot[:, j("LeftLeg"), 0] = 0.5 * np.maximum(swing, 0)
    rot[:, j("RightLeg"), 0] = 0.5 * np.maximum(-swing, 0)
    trans = np.repeat(body.rest_root_position()[None], frames, 0)
    trans[:, 1] -= speed * np.cumsum(ramp) / 30.0
    trans[:, 2] += 0.015 * np.cos(2 * phase) * ramp
    return Motion(rot, trans, 30.0, body.rig, body.joint_names, "walk")


def jump(body, frames: int, height: float = 0.25, period: float = 0.8) -> Motion:
    """Vertical hops: the root rises and falls on a parabola, ``height`` m, one hop per ``period`` s."""
    t = np.arange(frames) / 30.0
    u = (t % period) / period
    rot = np.zeros((frames, body.num_joints, 3), np.float32)
    trans = np.repeat(body.rest_root_position()[None], frames, 0)
    trans[:, 2] += 4 * height * u * (1 - u)
    return Motion(rot, trans, 30.0, body.rig, body.joint_names, "jump")


@pytest.fixture(scope="session")
def skirt(body):
    """A 448-vertex skirt (14 rings of 32), knee length."""
    return ring_skirt(body, n_around=32, n_down=14)
