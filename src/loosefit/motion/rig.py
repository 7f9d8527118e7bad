"""The rig a motion is retargeted onto, and which of its joints play the parts retargeting needs
(root, legs, feet, spine, arms, up axis)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loosefit.errors import InputError


@dataclass(frozen=True)
class Roles:
    """Which joints of a rig play the parts retargeting needs.

    Attributes:
        root: the root joint (pelvis).
        legs: ``((hip, knee, ankle) left, (hip, knee, ankle) right)``.
        feet: joints that touch the floor when standing (ankles, toes).
        spine: the chain from the root towards the head, root excluded.
        arms: ``(left, right)`` shoulder (upper-arm) joints, for the body's left-right axis.
        up: the rig's up axis in its rest frame.
    """

    root: str
    legs: tuple[tuple[str, str, str], tuple[str, str, str]]
    feet: tuple[str, ...]
    spine: tuple[str, ...]
    arms: tuple[str, str]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)


#: Roles per rig name: ``cmu_mb`` (Anny, CMU names) and ``smplh`` (SMPL-H, see :mod:`loosefit.motion.amass`).
RIG_ROLES = {
    "cmu_mb": Roles(
        root="Hips",
        legs=(("LeftUpLeg", "LeftLeg", "LeftFoot"), ("RightUpLeg", "RightLeg", "RightFoot")),
        feet=("LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase"),
        spine=("LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head"),
        arms=("LeftArm", "RightArm"),
    ),
    "smplh": Roles(
        root="pelvis",
        legs=(("left_hip", "left_knee", "left_ankle"), ("right_hip", "right_knee", "right_ankle")),
        feet=("left_ankle", "left_foot", "right_ankle", "right_foot"),
        spine=("spine1", "spine2", "spine3", "neck", "head"),
        arms=("left_shoulder", "right_shoulder"),
        up=(0.0, 1.0, 0.0),
    ),
}


@dataclass
class TargetRig:
    """The rig motions are retargeted onto.

    Attributes:
        name: rig name (a key of :data:`RIG_ROLES`).
        joint_names: ``J`` joint names.
        parents: ``(J,)`` parent indices, -1 for the root.
        rest: ``(J, 3)`` rest joint positions, metres, in the rig's rest frame (world-aligned joints).
    """

    name: str
    joint_names: list[str]
    parents: np.ndarray
    rest: np.ndarray

    @classmethod
    def from_body(cls, body) -> "TargetRig":
        """The rig of a :class:`~loosefit.body.BodyModel` in its own shape."""
        return cls(body.rig, list(body.joint_names), np.asarray(body.parents), body.rest_joints().astype(np.float64))

    @property
    def roles(self) -> Roles:
        if self.name not in RIG_ROLES:
            raise InputError(f"no retargeting roles for rig {self.name!r} (known: {sorted(RIG_ROLES)})")
        return RIG_ROLES[self.name]

