"""Anatomical joint limits for the ``cmu_mb`` rig, and the swing-twist joint parameters they live in.

A local joint rotation (rig convention of :mod:`loosefit.geometry.lbs`: world-aligned axes at
rest) is described by three *anatomical parameters* ``(sx, sy, tw)`` in radians:

- the joint's anatomical frame ``B`` (columns ``x, y, z``) has ``z`` along the bone and ``x`` on the
  main flexion axis; it is the world frame for the spine, neck, head, clavicles and legs (whose
  bones are vertical or whose flexion axis is the body's left-right axis), and follows the bones
  of the arms (which hang at ~45 degrees in Anny's A-pose);
- the rotation in that frame, ``B^T R B``, is split into a *twist* ``tw`` about ``z`` applied first
  and a *swing* ``exp([sx, sy, 0])`` applied after it. The swing-twist split is unique for swings
  below 180 degrees, so limits on ``(sx, sy, tw)`` are free of Euler-angle gimbal problems.

Right-side joints are described by the parameters of their left mirror image (mirroring the body
across its sagittal plane ``x = 0``), so one table of left-side limits serves both sides.

Sign conventions (left side, ``x`` = body left, ``y`` = body back, ``z`` = up):

- legs: hip ``sx < 0`` flexes (foot forward), hip ``sy < 0`` abducts; knee ``sx > 0`` bends (foot
  backward; Anny's rest knee is bent by ~10 degrees, so ``sx = -10 deg`` is a straight leg); ankle
  ``sx > 0`` points the toes down (plantar flexion); toe ``sx < 0`` lifts the toes; ``tw > 0`` turns
  the toes outward;
- spine, neck, head: ``sx > 0`` bends forward, ``sy > 0`` bends to the body's left, ``tw > 0``
  turns to the left;
- clavicle: ``sy < 0`` raises the shoulder;
- shoulder (``Arm``): ``sx > 0`` raises the arm forward, ``sy < 0`` raises it sideways (abduction
  from the A-pose), ``tw`` rotates it about its own axis;
- elbow (``ForeArm``): ``sx > 0`` bends (the rest pose is already bent ~45 degrees, so
  ``sx = -45 deg`` is a straight arm), ``tw`` is forearm pronation / supination.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from loosefit.errors import InputError
from loosefit.geometry.vectors import unit
from loosefit.motion.motion import Motion

_DEG = np.pi / 180.0


@dataclass(frozen=True)
class JointLimit:
    """Ranges of one joint's anatomical parameters, radians.

    Attributes:
        swing_x: ``(lo, hi)`` of ``sx``, the swing about the flexion axis.
        swing_y: ``(lo, hi)`` of ``sy``, the swing about the third axis.
        twist: ``(lo, hi)`` of ``tw``, the rotation about the bone.
        max_swing: bound on the total swing angle ``|(sx, sy)|`` (keeps combined swings short of 180 degrees).
    """

    swing_x: tuple[float, float]
    swing_y: tuple[float, float]
    twist: tuple[float, float]
    max_swing: float = np.pi


def _deg(sx, sy, tw, max_swing=180.0) -> JointLimit:
    return JointLimit(
        (sx[0] * _DEG, sx[1] * _DEG), (sy[0] * _DEG, sy[1] * _DEG), (tw[0] * _DEG, tw[1] * _DEG), max_swing * _DEG
    )


#: Left-side and central limits by side-less joint name (see the module docstring for signs).
LIMITS: dict[str, JointLimit] = {
    "HipJoint": _deg((-5, 5), (-5, 5), (-5, 5)),
    "UpLeg": _deg((-125, 35), (-50, 30), (-45, 45)),
    "Leg": _deg((-10, 150), (-5, 5), (-15, 15)),
    "Foot": _deg((-40, 55), (-25, 25), (-30, 30)),
    "ToeBase": _deg((-60, 30), (-10, 10), (-10, 10)),
    "LowerBack": _deg((-20, 40), (-25, 25), (-30, 30)),
    "Spine": _deg((-20, 40), (-25, 25), (-30, 30)),
    "Spine1": _deg((-20, 40), (-25, 25), (-30, 30)),
    "Neck": _deg((-40, 45), (-30, 30), (-45, 45)),
    "Neck1": _deg((-40, 45), (-30, 30), (-45, 45)),
    "Head": _deg((-30, 30), (-25, 25), (-40, 40)),
    "Shoulder": _deg((-20, 20), (-30, 10), (-25, 25)),
    "Arm": _deg((-50, 160), (-130, 45), (-80, 80), max_swing=170),
    "ForeArm": _deg((-45, 100), (-5, 5), (-80, 80)),
    "Hand": _deg((-70, 70), (-30, 30), (-10, 10)),
    "Thumb": _deg((-20, 20), (-20, 20), (-10, 10)),
    "FingerBase": _deg((-20, 20), (-20, 20), (-10, 10)),
    "HandFinger1": _deg((-20, 20), (-20, 20), (-10, 10)),
}

#: The joint left free (global orientation).
ROOT = "Hips"

# Mirroring across x = 0 maps an axis-angle vector (a, b, c) to (a, -b, -c).
_MIRROR = np.array([1.0, -1.0, -1.0])


def side_of(name: str) -> tuple[str, str]:
    """``(side, generic)`` of a cmu_mb joint name: ``("R", "UpLeg")`` for ``"RightUpLeg"``,
    ``("L", "HipJoint")`` for ``"LHipJoint"``, ``("", "Spine")`` for central joints."""
    for prefix, side in (("Left", "L"), ("Right", "R")):
        if name.startswith(prefix):
            return side, name[len(prefix) :]
    if name in ("LHipJoint", "RHipJoint", "LThumb", "RThumb"):
        return name[0], name[1:]
    return "", name


def _frame(x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Right-handed frame (columns ``x, y, z``) with ``z`` along ``z`` and ``x`` as close to ``x`` as possible."""
    z = unit(z)
    x = unit(x - (x @ z) * z)
    return np.stack([x, np.cross(z, x), z], 1)


def _arm_frames(names: list[str], rest: np.ndarray) -> dict[str, np.ndarray]:
    """Anatomical frames of the left arm chain, built from the rest joint positions."""
    pos = {n: rest[names.index(n)].astype(np.float64) for n in names}
    upper = unit(pos["LeftForeArm"] - pos["LeftArm"])
    fore = unit(pos["LeftHand"] - pos["LeftForeArm"])
    hand = unit(pos["LeftFingerBase"] - pos["LeftHand"])
    # Shoulder: positive swing about x carries the arm forward (-y).
    shoulder = _frame(np.cross(upper, [0.0, -1.0, 0.0]), upper)
    # Elbow: positive swing about x folds the forearm onto the upper arm.
    elbow = _frame(np.cross(upper, fore), fore)
    wrist = _frame(elbow[:, 0], hand)
    return {"Arm": shoulder, "ForeArm": elbow, "Hand": wrist, "Thumb": wrist, "FingerBase": wrist, "HandFinger1": wrist}


# Small numpy quaternion helpers ``(..., 4)`` as (w, x, y, z): the swing-twist split runs on every
# frame of every generated motion, and numpy is much faster than torch on these small arrays.
def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions ``(..., 4)``."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        -1,
    )


def _quat(aa: np.ndarray) -> np.ndarray:
    """Axis-angle ``(..., 3)`` -> unit quaternions ``(..., 4)``."""
    angle = np.linalg.norm(aa, axis=-1, keepdims=True)
    # sin(angle / 2) / angle, with its Taylor series near zero.
    k = np.where(angle < 1e-6, 0.5 - angle * angle / 48, np.sin(angle / 2) / np.where(angle < 1e-6, 1.0, angle))
    return np.concatenate([np.cos(angle / 2), aa * k], -1)


def _axis_angle(q: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` -> axis-angle ``(..., 3)`` with angle in ``[0, pi]``."""
    q = np.where(q[..., :1] < 0, -q, q)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2 * np.arctan2(s, q[..., :1])
    small = s < 1e-9
    return q[..., 1:] * np.where(small, 2.0 / np.maximum(q[..., :1], 1e-12), angle / np.where(small, 1.0, s))


def swing_twist(aa) -> np.ndarray:
    """Split rotations ``(..., 3)`` axis-angle into ``(..., 3)`` ``(sx, sy, tw)``: twist ``tw`` about
    ``z`` first, then the swing ``exp([sx, sy, 0])``. Twist in ``[-pi, pi]``."""
    q = _quat(np.asarray(aa, dtype=np.float64))
    q = np.where(q[..., :1] < 0, -q, q)
    tw = 2.0 * np.arctan2(q[..., 3], q[..., 0])
    zero = np.zeros_like(tw)
    swing = _axis_angle(_qmul(q, np.stack([np.cos(tw / 2), zero, zero, -np.sin(tw / 2)], -1)))
    return np.concatenate([swing[..., :2], tw[..., None]], -1)


def from_swing_twist(params) -> np.ndarray:
    """Inverse of :func:`swing_twist`: ``(..., 3)`` ``(sx, sy, tw)`` -> ``(..., 3)`` axis-angle."""
    p = np.asarray(params, dtype=np.float64)
    swing = _quat(np.concatenate([p[..., :2], np.zeros_like(p[..., :1])], -1))
    zero = np.zeros_like(p[..., 2])
    twist = np.stack([np.cos(p[..., 2] / 2), zero, zero, np.sin(p[..., 2] / 2)], -1)
    return _axis_angle(_qmul(swing, twist))


class JointLimits:
    """Joint limits and anatomical parameters of a body on the ``cmu_mb`` rig.

    Args:
        body: a :class:`~loosefit.body.base.BodyModel` on rig ``cmu_mb`` (its rest joints give the
            arms' anatomical frames).

    Attributes:
        joint_names: the rig's ``J`` joint names.
        frames: ``(J, 3, 3)`` anatomical frames (columns ``x, y, z``) of the left-side or central joint
            each joint is described by.
        mirrored: ``(J,)`` bool, True for right-side joints.
        free: ``(J,)`` bool, True for the root (unlimited; its parameters are its axis-angle).
        lo, hi: ``(J, 3)`` float64 parameter ranges, radians.
        max_swing: ``(J,)`` float64 bound on ``|(sx, sy)|``, radians.
    """

    def __init__(self, body):
        if body.rig != "cmu_mb":
            raise InputError(f"joint limits are defined for rig 'cmu_mb', body {body.name} uses {body.rig!r}")
        self.joint_names = list(body.joint_names)
        J = len(self.joint_names)
        arm = _arm_frames(self.joint_names, body.rest_joints())
        self.frames = np.repeat(np.eye(3)[None], J, 0)
        self.mirrored = np.zeros(J, bool)
        self.free = np.zeros(J, bool)
        self.lo = np.full((J, 3), -np.pi)
        self.hi = np.full((J, 3), np.pi)
        self.max_swing = np.full(J, np.pi)
        for j, name in enumerate(self.joint_names):
            if name == ROOT:
                self.free[j] = True
                continue
            side, generic = side_of(name)
            if generic not in LIMITS:
                raise InputError(f"no joint limits for joint {name!r} of rig 'cmu_mb'")
            lim = LIMITS[generic]
            self.lo[j] = [lim.swing_x[0], lim.swing_y[0], lim.twist[0]]
            self.hi[j] = [lim.swing_x[1], lim.swing_y[1], lim.twist[1]]
            self.max_swing[j] = lim.max_swing
            self.mirrored[j] = side == "R"
            if generic in arm:
                self.frames[j] = arm[generic]

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    def index(self, name: str) -> int:
        return self.joint_names.index(name)

    def _to_frame(self, aa: np.ndarray) -> np.ndarray:
        aa = np.where(self.mirrored[:, None], aa * _MIRROR, aa)
        return np.einsum("jab,...ja->...jb", self.frames, aa)  # B^T aa per joint

    def _from_frame(self, aa: np.ndarray) -> np.ndarray:
        aa = np.einsum("jab,...jb->...ja", self.frames, aa)  # B aa per joint
        return np.where(self.mirrored[:, None], aa * _MIRROR, aa)

    def to_anatomical(self, rotations: np.ndarray) -> np.ndarray:
        """Local axis-angle rotations ``(..., J, 3)`` -> anatomical parameters ``(..., J, 3)``, radians
        (the root keeps its axis-angle)."""
        rotations = np.asarray(rotations, dtype=np.float64)
        params = swing_twist(self._to_frame(rotations))
        return np.where(self.free[:, None], rotations, params)

    def from_anatomical(self, params: np.ndarray) -> np.ndarray:
        """Anatomical parameters ``(..., J, 3)`` -> local axis-angle rotations ``(..., J, 3)``, float64."""
        params = np.asarray(params, dtype=np.float64)
        aa = self._from_frame(from_swing_twist(params))
        return np.where(self.free[:, None], params, aa)

    def clamp_anatomical(self, params: np.ndarray) -> np.ndarray:
        """Project anatomical parameters ``(..., J, 3)`` into the limits (root untouched)."""
        params = np.asarray(params, dtype=np.float64)
        out = np.clip(params, self.lo, self.hi)
        swing = np.linalg.norm(out[..., :2], axis=-1, keepdims=True)
        scale = np.minimum(1.0, self.max_swing[:, None] / np.maximum(swing, 1e-12))
        out[..., :2] *= scale
        return np.where(self.free[:, None], params, out)

    def excess(self, params: np.ndarray) -> np.ndarray:
        """``(..., J)`` radians by which anatomical parameters ``(..., J, 3)`` leave the limits (0 inside)."""
        params = np.asarray(params, dtype=np.float64)
        over = np.maximum(params - self.hi, 0.0) + np.maximum(self.lo - params, 0.0)
        cone = np.maximum(np.linalg.norm(params[..., :2], axis=-1) - self.max_swing, 0.0)
        return np.where(self.free, 0.0, np.maximum(over.max(-1), cone))

    def violation(self, motion: Motion) -> np.ndarray:
        """``(T, J)`` radians by which each joint of ``motion`` leaves its limits, per frame."""
        self._check_rig(motion)
        return self.excess(self.to_anatomical(motion.rotations))

    def clamp(self, motion: Motion) -> Motion:
        """``motion`` with every joint rotation projected into its limits (root and translation kept)."""
        self._check_rig(motion)
        params = self.clamp_anatomical(self.to_anatomical(motion.rotations))
        rot = self.from_anatomical(params).astype(np.float32)
        return Motion(rot, motion.translation, motion.fps, motion.rig, motion.joint_names, motion.name)

    def check(self, motion: Motion, tolerance: float = 1e-2) -> None:
        """Raise :class:`InputError` naming the worst joint and frame when ``motion`` leaves the
        limits by more than ``tolerance`` radians."""
        v = self.violation(motion)
        if v.size and v.max() > tolerance:
            t, j = np.unravel_index(np.argmax(v), v.shape)
            raise InputError(
                f"motion {motion.name!r} exceeds the limits of joint {self.joint_names[j]!r} by "
                f"{np.degrees(v[t, j]):.1f} deg at frame {t} ({int((v > tolerance).sum())} joint-frames out of limits)"
            )

    def _check_rig(self, motion: Motion) -> None:
        if motion.rig != "cmu_mb" or (motion.joint_names and list(motion.joint_names) != self.joint_names):
            raise InputError(f"motion {motion.name!r} is not on this body's cmu_mb rig")
        if motion.num_joints != self.num_joints:
            raise InputError(
                f"motion {motion.name!r} has {motion.num_joints} joints, rig 'cmu_mb' has {self.num_joints}"
            )


@functools.lru_cache(maxsize=8)
def _cached(body) -> JointLimits:
    return JointLimits(body)


def joint_limits(body) -> JointLimits:
    """The :class:`JointLimits` of ``body`` (built once per body object)."""
    return _cached(body)


def clamp_motion(motion: Motion, body) -> Motion:
    """``motion`` with its joint rotations clamped into the limits of ``body``'s rig."""
    return joint_limits(body).clamp(motion)


def check_motion(motion: Motion, body, tolerance: float = 1e-2) -> None:
    """Raise :class:`InputError` when ``motion`` leaves the joint limits by more than ``tolerance`` radians."""
    joint_limits(body).check(motion, tolerance)
