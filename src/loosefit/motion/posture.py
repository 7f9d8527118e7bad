"""Upper-body posture builder: anatomical joint parameters from a few named body-level angles.

:class:`Posture` accumulates ``(T, J, 3)`` anatomical parameters (see :mod:`loosefit.motion.limits`)
for the spine, neck, head, clavicles and arms in terms a generator thinks in: bend the spine
forward by 20 degrees, raise the left arm sideways to the horizontal, bend the elbow to 90 degrees.
Arm angles are measured from the anatomical neutral (arm hanging straight down, elbow straight),
not from Anny's A-pose rest.
"""

from __future__ import annotations

import numpy as np

from loosefit.motion.curves import smooth_noise
from loosefit.motion.kinematics import Skeleton

SPINE = ("LowerBack", "Spine", "Spine1")
NECK = ("Neck", "Neck1", "Head")
_SPINE_SHARE = np.array([0.3, 0.35, 0.35])
_NECK_SHARE = np.array([0.35, 0.35, 0.3])
SIDES = ("Left", "Right")


def _angle(u: np.ndarray, v: np.ndarray) -> float:
    return float(np.arccos(np.clip(u @ v / (np.linalg.norm(u) * np.linalg.norm(v)), -1.0, 1.0)))


class Posture:
    """Anatomical parameters of ``T`` frames, built by adding named angles (radians, arrays ``(T,)``
    or scalars). Leg joints are left at zero (the legs are solved by inverse kinematics)."""

    def __init__(self, skel: Skeleton, num_frames: int):
        self.skel = skel
        self.params = np.zeros((num_frames, skel.num_joints, 3))
        rest = skel.rest
        ix = skel.index
        # Anny's A-pose: the upper arm hangs out sideways, the elbow is already bent.
        upper = rest[ix("LeftForeArm")] - rest[ix("LeftArm")]
        fore = rest[ix("LeftHand")] - rest[ix("LeftForeArm")]
        self.rest_abduction = _angle(upper, np.array([0.0, 0.0, -1.0]))
        self.rest_elbow = _angle(upper, fore)

    def joint(self, name: str, sx=0.0, sy=0.0, tw=0.0) -> "Posture":
        """Add ``(sx, sy, tw)`` to one joint's parameters."""
        T = self.params.shape[0]
        self.params[:, self.skel.index(name)] += np.stack(
            [np.broadcast_to(np.asarray(v, dtype=np.float64), (T,)) for v in (sx, sy, tw)], -1
        )
        return self

    def spine(self, bend=0.0, side=0.0, twist=0.0) -> "Posture":
        """Spread a forward ``bend``, a ``side`` bend (+ to the body's left) and a ``twist`` (+ turns
        the chest to the left) over the three spine joints."""
        for name, w in zip(SPINE, _SPINE_SHARE):
            self.joint(name, w * np.asarray(bend), w * np.asarray(side), w * np.asarray(twist))
        return self

    def head(self, nod=0.0, tilt=0.0, turn=0.0) -> "Posture":
        """Spread a forward ``nod``, a ``tilt`` (+ to the left) and a ``turn`` (+ to the left) over
        the neck and head."""
        for name, w in zip(NECK, _NECK_SHARE):
            self.joint(name, w * np.asarray(nod), w * np.asarray(tilt), w * np.asarray(turn))
        return self

    def arm(
        self, side: int, flex=0.0, abduct=None, twist=0.0, elbow=None, pronate=0.0, wrist=0.0, shrug=0.0
    ) -> "Posture":
        """Pose one arm (``side`` 0 left, 1 right; mirror-symmetric values give a symmetric pose).

        Args:
            flex: forward raise of the upper arm (+ forward).
            abduct: sideways angle of the upper arm from hanging straight down (``pi/2`` horizontal);
                ``None`` keeps the A-pose.
            twist: rotation of the upper arm about itself.
            elbow: elbow flexion, 0 straight; ``None`` keeps the rest bend.
            pronate: forearm rotation about itself.
            wrist: wrist flexion.
            shrug: clavicle elevation.
        """
        s = SIDES[side]
        sy = 0.0 if abduct is None else self.rest_abduction - np.asarray(abduct)
        sx_elbow = 0.0 if elbow is None else np.asarray(elbow) - self.rest_elbow
        self.joint(f"{s}Shoulder", 0.0, -np.asarray(shrug), 0.0)
        self.joint(f"{s}Arm", flex, sy, twist)
        self.joint(f"{s}ForeArm", sx_elbow, 0.0, pronate)
        self.joint(f"{s}Hand", wrist, 0.0, 0.0)
        return self

    def idle(self, rng: np.random.Generator, t: np.ndarray, amount: float = 1.0) -> "Posture":
        """Add slow small random motion everywhere (breathing, balance, fidgeting); ``amount`` scales it."""
        d = np.radians(amount)
        self.spine(smooth_noise(rng, t, 2.0, 2 * d), smooth_noise(rng, t, 2.5, 2 * d), smooth_noise(rng, t, 3.0, 3 * d))
        self.head(smooth_noise(rng, t, 1.5, 4 * d), smooth_noise(rng, t, 2.0, 3 * d), smooth_noise(rng, t, 2.0, 6 * d))
        for side in (0, 1):
            self.arm(side, flex=smooth_noise(rng, t, 2.0, 4 * d), abduct=None, elbow=None)
            self.joint(f"{SIDES[side]}ForeArm", smooth_noise(rng, t, 2.0, 4 * d))
            self.joint(f"{SIDES[side]}Hand", smooth_noise(rng, t, 1.5, 6 * d))
        return self
