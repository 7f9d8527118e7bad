"""From a performance (pelvis path, foot targets, upper-body joint parameters) to rig rotations.

The procedural generators describe a motion as a :class:`Performance`: where the pelvis is and how
it is oriented, where each ankle should be and how each foot is oriented, and anatomical
parameters (:mod:`loosefit.motion.limits`) for the spine, arms and head. :func:`solve` turns it into
local joint rotations: the legs by analytic two-bone inverse kinematics (the knee bends only
forward, the knee points where the foot points), the feet flat or tilted as asked, then every
joint clamped into its limits.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch

from loosefit.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from loosefit.geometry.vectors import unit
from loosefit.motion.limits import JointLimits, joint_limits

#: Leg joints per side (index 0 = left, 1 = right) in chain order: hip socket, thigh, shank, foot, toes.
LEG_JOINTS = (
    ("LHipJoint", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"),
    ("RHipJoint", "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase"),
)
#: Lateral sign per side: the body's left is +x.
SIDE_SIGN = np.array([1.0, -1.0])
# Beyond this fraction of the full leg length the knee straightens asymptotically instead of locking.
_SOFT_REACH = 0.99


def rot_x(a) -> np.ndarray:
    """Rotations ``(..., 3, 3)`` about x by angles ``a (...)``, radians."""
    a = np.asarray(a, dtype=np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([o, z, z, z, c, -s, z, s, c], -1).reshape(a.shape + (3, 3))


def rot_y(a) -> np.ndarray:
    """Rotations ``(..., 3, 3)`` about y by angles ``a (...)``, radians."""
    a = np.asarray(a, dtype=np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([c, z, s, z, o, z, -s, z, c], -1).reshape(a.shape + (3, 3))


def rot_z(a) -> np.ndarray:
    """Rotations ``(..., 3, 3)`` about z by angles ``a (...)``, radians."""
    a = np.asarray(a, dtype=np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([c, -s, z, s, c, z, z, z, o], -1).reshape(a.shape + (3, 3))


def yaw_rotate(xy: np.ndarray, yaw) -> np.ndarray:
    """Rotate horizontal vectors ``(..., 2)`` by ``yaw (...)`` radians about z."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], -1)


def pelvis_rotation(yaw, pitch, roll) -> np.ndarray:
    """``(T, 3, 3)`` world rotation of the pelvis: heading ``yaw`` (+ turns left), then ``pitch``
    (+ leans forward) and ``roll`` (+ drops the left hip), radians."""
    return rot_z(yaw) @ rot_x(pitch) @ rot_y(roll)


def _orthogonal(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    return unit(v - (v * axis).sum(-1, keepdims=True) * axis)


def _to_axis_angle(R: np.ndarray) -> np.ndarray:
    return matrix_to_axis_angle(torch.from_numpy(np.ascontiguousarray(R))).numpy()


def _matrix(aa: np.ndarray) -> np.ndarray:
    """Axis-angle ``(..., 3)`` -> rotation matrices ``(..., 3, 3)`` (float64)."""
    return axis_angle_to_matrix(torch.from_numpy(np.asarray(aa, dtype=np.float64))).numpy()


@dataclass(frozen=True)
class Skeleton:
    """Body measurements the generators need, in metres, from the body's rest joints.

    Attributes:
        limits: the body's :class:`~loosefit.motion.limits.JointLimits`.
        rest: ``(J, 3)`` rest joint positions.
        root: ``(3,)`` rest root (pelvis) position.
        hip, knee, ankle, toe: ``(2, 3)`` rest positions per side (0 left, 1 right).
        leg_length: hip to ankle with the knee at its rest bend (mean of both sides).
    """

    limits: JointLimits
    rest: np.ndarray
    root: np.ndarray
    hip: np.ndarray
    knee: np.ndarray
    ankle: np.ndarray
    toe: np.ndarray
    leg_length: float

    @classmethod
    def from_body(cls, body) -> "Skeleton":
        limits = joint_limits(body)
        rest = body.rest_joints().astype(np.float64)
        pos = lambda k: np.stack([rest[limits.index(LEG_JOINTS[s][k])] for s in (0, 1)])  # noqa: E731
        hip, knee, ankle, toe = pos(1), pos(2), pos(3), pos(4)
        leg_length = float(np.linalg.norm(ankle - hip, axis=1).mean())
        return cls(limits, rest, rest[0].copy(), hip, knee, ankle, toe, leg_length)

    def index(self, name: str) -> int:
        return self.limits.index(name)

    @property
    def num_joints(self) -> int:
        return self.limits.num_joints

    @property
    def toe_height(self) -> float:
        """Height of the toe joints when the foot is flat on the floor."""
        return float(self.toe[:, 2].mean())

    def _knee_range(self, side: int) -> tuple[float, float]:
        j = self.index(LEG_JOINTS[side][2])
        return max(self.limits.lo[j, 0], self._knee_terms(side)[2]), self.limits.hi[j, 0]

    def max_reach(self, side: int) -> float:
        """Hip-to-ankle distance of the leg with the knee as straight as its limit allows."""
        K, R, phi = self._knee_terms(side)
        return float(np.sqrt(K + R * np.cos(self._knee_range(side)[0] - phi)))

    def _knee_terms(self, side: int) -> tuple[float, float, float]:
        # |thigh + Rx(a) shin|^2 = K + R cos(a - phi)
        t, s = self.knee[side] - self.hip[side], self.ankle[side] - self.knee[side]
        K = t @ t + s @ s + 2 * t[0] * s[0]
        A = 2 * (t[1] * s[1] + t[2] * s[2])
        B = 2 * (t[2] * s[1] - t[1] * s[2])
        return float(K), float(np.hypot(A, B)), float(np.arctan2(B, A))

    def knee_angle(self, side: int, distance: np.ndarray) -> np.ndarray:
        """Knee flexion ``(T,)`` (radians, relative to the rest pose) putting the ankle at
        ``distance (T,)`` from the hip; targets beyond 99% of the reach straighten the knee smoothly
        instead of locking it."""
        K, R, phi = self._knee_terms(side)
        lo, hi = self._knee_range(side)
        full = self.max_reach(side)
        x = np.asarray(distance, dtype=np.float64) / full
        u = (x - _SOFT_REACH) / (1 - _SOFT_REACH)
        x = np.where(u > 0, _SOFT_REACH + (1 - _SOFT_REACH) * np.tanh(np.maximum(u, 0)), x)
        c = np.clip(((x * full) ** 2 - K) / R, -1.0, 1.0)
        return np.clip(phi + np.arccos(c), lo, hi)

    def hip_offsets(self) -> np.ndarray:
        """``(2, 3)`` hips relative to the root at rest."""
        return self.hip - self.root


@dataclass
class Performance:
    """A motion before inverse kinematics, ``T`` frames. Index 0 of the foot axes is the left foot.

    Attributes:
        root: ``(T, 3)`` world position of the root joint (pelvis), metres.
        yaw, pitch, roll: ``(T,)`` pelvis orientation, radians (see :func:`pelvis_rotation`).
        ankle: ``(T, 2, 3)`` ankle targets, world, metres.
        foot_yaw, foot_pitch: ``(T, 2)`` foot orientation in the world when it is placed (pitch + lifts
            the heel), radians; the knee points along ``foot_yaw``.
        foot_free: ``(T, 2)`` in ``[0, 1]``: 1 orients the foot by ``ankle_flex`` relative to the shank
            instead of by ``foot_yaw`` / ``foot_pitch`` (feet in the air).
        ankle_flex: ``(T, 2)`` ankle plantar flexion used when the foot is free, radians.
        anat: ``(T, J, 3)`` anatomical parameters of the other joints (legs and root are ignored).
    """

    root: np.ndarray
    yaw: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    ankle: np.ndarray
    foot_yaw: np.ndarray
    foot_pitch: np.ndarray
    foot_free: np.ndarray
    ankle_flex: np.ndarray
    anat: np.ndarray

    @property
    def num_frames(self) -> int:
        return self.root.shape[0]

    def transformed(self, yaw: float, offset) -> "Performance":
        """The same performance turned by ``yaw`` radians about the world z axis, then moved by ``offset (2,)``."""
        out = Performance(**{f.name: getattr(self, f.name).copy() for f in fields(self)})
        offset = np.asarray(offset, dtype=np.float64)
        out.root[:, :2] = yaw_rotate(self.root[:, :2], yaw) + offset
        out.ankle[..., :2] = yaw_rotate(self.ankle[..., :2], yaw) + offset
        out.yaw += yaw
        out.foot_yaw += yaw
        return out

    def slice(self, start: int, stop: int) -> "Performance":
        return Performance(**{f.name: getattr(self, f.name)[start:stop].copy() for f in fields(self)})


def blend(a: Performance, b: Performance, w: np.ndarray) -> Performance:
    """Frame-wise cross-fade ``(1 - w) a + w b`` of two performances of equal length, ``w (T,)``."""
    out = {}
    for f in fields(Performance):
        x, y = getattr(a, f.name), getattr(b, f.name)
        ww = w.reshape((-1,) + (1,) * (x.ndim - 1))
        out[f.name] = (1 - ww) * x + ww * y
    return Performance(**out)


def root_height_limit(skel: Skeleton, root_xy, yaw, pitch, roll, ankle, reach: float = 0.99) -> np.ndarray:
    """Highest root height per frame and foot ``(T, 2)`` at which each ankle target ``(T, 2, 3)`` is
    within ``reach`` times the leg's full reach, for the pelvis at ``root_xy (T, 2)`` with the given
    orientation ``(T,)``. A target farther away horizontally than the reach gets the height that puts
    the hip level with it."""
    W = pelvis_rotation(yaw, pitch, roll)
    out = np.empty(ankle.shape[:2])
    for side in (0, 1):
        hip = np.einsum("tab,b->ta", W, skel.hip_offsets()[side])
        dxy = np.linalg.norm(root_xy + hip[:, :2] - ankle[:, side, :2], axis=-1)
        r = reach * skel.max_reach(side)
        out[:, side] = ankle[:, side, 2] - hip[:, 2] + np.sqrt(np.maximum(r * r - dxy * dxy, 0.0))
    return out


def _aim(leg: np.ndarray, target: np.ndarray, hinge: np.ndarray) -> np.ndarray:
    """Hip rotations ``(T, 3, 3)`` turning the rest leg direction ``leg (T, 3)`` onto ``target (T, 3)``
    and then twisting about it so that the knee's hinge (the x axis at rest) lines up with ``hinge (T, 3)``.
    Where ``hinge`` nearly runs along the leg the twist fades out (no flips)."""
    a, b = unit(leg), unit(target)
    axis = np.cross(a, b)
    sin, cos = np.linalg.norm(axis, axis=-1), (a * b).sum(-1)
    swing = _matrix(unit(axis) * np.arctan2(sin, cos)[:, None])
    x_rest = _orthogonal(np.broadcast_to(np.array([1.0, 0.0, 0.0]), a.shape), a)
    x_now = np.einsum("tab,tb->ta", swing, x_rest)
    h = hinge - (hinge * b).sum(-1, keepdims=True) * b
    strength = np.linalg.norm(h, axis=-1)
    h = h / strength[:, None].clip(1e-12)
    twist = np.arctan2((np.cross(x_now, h) * b).sum(-1), (x_now * h).sum(-1))
    fade = np.clip(strength / 0.5, 0.0, 1.0)
    fade = fade * fade * (3 - 2 * fade)
    return _matrix(b * (twist * fade)[:, None]) @ swing


def solve(perf: Performance, skel: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Local joint rotations for a performance.

    Returns:
        ``rotations (T, J, 3)`` float32 axis-angle (clamped into the joint limits) and
        ``translation (T, 3)`` float32 root positions.
    """
    T = perf.num_frames
    limits = skel.limits
    W = pelvis_rotation(perf.yaw, perf.pitch, perf.roll)
    aa = limits.from_anatomical(perf.anat)
    aa[:, 0] = _to_axis_angle(W)
    for side in (0, 1):
        socket, thigh, shank, foot, toes = (limits.index(n) for n in LEG_JOINTS[side])
        # The thigh hangs from the hip socket joint, a child of the root.
        W_socket = W @ _matrix(aa[:, socket])
        hip_world = (perf.root + W @ (skel.rest[socket] - skel.root)
                     + W_socket @ (skel.hip[side] - skel.rest[socket]))
        d = np.einsum("tba,tb->ta", W_socket, perf.ankle[:, side] - hip_world)  # in the socket's frame
        theta = skel.knee_angle(side, np.linalg.norm(d, axis=-1))
        t_vec, s_vec = skel.knee[side] - skel.hip[side], skel.ankle[side] - skel.knee[side]
        leg = unit(t_vec + np.einsum("tab,b->ta", rot_x(theta), s_vec))
        hinge_world = np.stack([np.cos(perf.foot_yaw[:, side]), np.sin(perf.foot_yaw[:, side]), np.zeros(T)], -1)
        R_hip = _aim(leg, d, np.einsum("tba,tb->ta", W_socket, hinge_world))
        R_knee = rot_x(theta)
        shank_world = W_socket @ R_hip @ R_knee
        foot_world = rot_z(perf.foot_yaw[:, side]) @ rot_x(perf.foot_pitch[:, side])
        aa[:, thigh] = _to_axis_angle(R_hip)
        aa[:, shank] = _to_axis_angle(R_knee)
        aa[:, foot] = _to_axis_angle(np.swapaxes(shank_world, -1, -2) @ foot_world)
        # Blend the placed foot with the free ankle in parameter space (both are the same joint).
        params = limits.to_anatomical(aa)
        free = perf.foot_free[:, side, None]
        params[:, foot] = (1 - free) * params[:, foot] + free * np.stack(
            [perf.ankle_flex[:, side], np.zeros(T), np.zeros(T)], -1
        )
        # Toes stay flat on the floor while the heel is lifted.
        params[:, toes] = 0.0
        params[:, toes, 0] = -np.maximum(perf.foot_pitch[:, side], 0.0) * (1 - perf.foot_free[:, side])
        aa = limits.from_anatomical(params)
    params = limits.clamp_anatomical(limits.to_anatomical(aa))
    rotations = limits.from_anatomical(params)
    return rotations.astype(np.float32), perf.root.astype(np.float32)
