"""Left-right mirrored motions: a motion's reflection through the body's plane of symmetry.

The rig convention (:mod:`loosefit.geometry.lbs`) has world-aligned joint frames at rest, so reflecting a
pose through the plane ``x = 0`` (the body's left-right axis is X: the default Anny body is symmetric about
that plane to a micrometre) needs no per-joint frame algebra. With ``M = diag(-1, 1, 1)``, every local rotation
``R`` becomes ``M R M``, whose rotation vector is ``(r_x, -r_y, -r_z)`` (a rotation vector is a pseudo-vector:
``det(M) M r``); the left and right joints trade their rotations, and the root translation becomes
``M t``. The posed skeleton of the mirrored motion is then exactly the mirror image of the original's,
joint ``j``'s place taken by its partner (``tests/motion/test_mirror.py`` checks it against forward kinematics).
A clockwise spin becomes a counter-clockwise one, a kick of the left leg a kick of the right.
"""

from __future__ import annotations

import re

import numpy as np

from loosefit.errors import InputError
from loosefit.motion.motion import Motion

#: The reflection through the plane of symmetry, ``x -> -x``.
REFLECTION = np.diag([-1.0, 1.0, 1.0])
#: A rig is left-right symmetric when each joint's rest position, mirrored, is within this of its partner's, m
#: (the default Anny body's ``Neck1`` stands 1.5 mm off the midline; its vertices are symmetric to a micrometre).
SYMMETRY_TOLERANCE = 5e-3

# Left/right spellings: "LeftArm", "left_hip", "LEFT_KNEE" (the word, in any case), "LHipJoint", "hip_l".
_SIDES = (
    (re.compile(r"left|right", re.IGNORECASE), None, None),
    (re.compile(r"^L(?=[A-Z])"), "L", "R"),
    (re.compile(r"^R(?=[A-Z])"), "R", "L"),
    (re.compile(r"_l$"), "_l", "_r"),
    (re.compile(r"_r$"), "_r", "_l"),
)


def _partner_name(name: str) -> str | None:
    """The name of the other side's joint, or ``None`` for a name that names no side."""
    for pattern, this, other in _SIDES:
        match = pattern.search(name)
        if match is None:
            continue
        if this is None:  # the word, swapped in the same case
            word = match.group(0)
            swap = "right" if word.lower() == "left" else "left"
            swap = swap.upper() if word.isupper() else swap.capitalize() if word[0].isupper() else swap
            return name[: match.start()] + swap + name[match.end():]
        return name[: match.start()] + other + name[match.end():]
    return None


def joint_partners(joint_names, rest_joints: np.ndarray | None = None) -> np.ndarray:
    """Each joint's left-right partner.

    Args:
        joint_names: ``J`` names of a rig.
        rest_joints: ``(J, 3)`` rest positions, m; when given, the pairing is checked against them: each
            joint mirrored must land on its partner within :data:`SYMMETRY_TOLERANCE`.

    Returns:
        ``(J,)`` int64: ``partners[j]`` is the other side's joint, or ``j`` for a joint on the midline.

    Raises:
        InputError: a side joint without its partner in the rig, or a rig that is not symmetric.
    """
    names = list(joint_names)
    index = {n: i for i, n in enumerate(names)}
    partners = np.arange(len(names), dtype=np.int64)
    for j, name in enumerate(names):
        other = _partner_name(name)
        if other is None:
            continue
        if other not in index:
            raise InputError(f"joint {name!r} names a side but the rig has no {other!r} to mirror it to")
        partners[j] = index[other]
    if rest_joints is not None:
        rest = np.asarray(rest_joints, np.float64)
        miss = np.linalg.norm(rest[partners] - rest @ REFLECTION, axis=1)
        if miss.max() > SYMMETRY_TOLERANCE:
            worst = int(miss.argmax())
            raise InputError(f"the rig is not left-right symmetric about x = 0: joint {names[worst]!r} mirrored is "
                             f"{1e3 * miss[worst]:.1f} mm from {names[partners[worst]]!r} "
                             f"(tolerance {1e3 * SYMMETRY_TOLERANCE:g} mm)")
    return partners


def mirror_motion(motion: Motion, partners: np.ndarray) -> Motion:
    """``motion`` reflected through ``x = 0`` (module docstring).

    Args:
        motion: ``rotations (T, J, 3)`` axis-angle, ``translation (T, 3)`` m.
        partners: ``(J,)`` from :func:`joint_partners`.

    Returns:
        The mirrored :class:`Motion`, named ``<name> mirrored``; mirroring it again gives ``motion`` back.
    """
    partners = np.asarray(partners, np.int64)
    if partners.shape != (motion.num_joints,):
        raise InputError(f"{len(partners)} joint partners for a motion of {motion.num_joints} joints")
    rotations = motion.rotations[:, partners] * np.array([1.0, -1.0, -1.0], np.float32)
    translation = motion.translation * np.array([-1.0, 1.0, 1.0], np.float32)
    return Motion(rotations, translation, motion.fps, motion.rig, motion.joint_names, f"{motion.name} mirrored".strip())
