"""A quasi-static version of a motion: key poses, each reached in a short transition and then held until
the cloth settles.

Playing a motion slower (:func:`loosefit.motion.resample.slow_down`) only weakens the cloth's inertia; a
held pose removes it: after ``hold`` frames at rest the garment is near its static equilibrium for that
pose, which is the ground truth a static method (FitGar) is built for. The settled frame of key ``k`` is
frame ``(k + 1) * (transition + hold) - 1`` of the result (:func:`settled_frames`).

A held pose is still reached from the previous key, and a loose garment's rest shape depends on the way
it came: a dress's hem stays where the last stride put it, so one pose has several drapes and a network
of the pose learns their mean. ``from_rest`` removes that memory: between keys the body goes back to its
rest pose (every joint unrotated, the root turned only to the key's heading) and holds it, so that every
key is reached along the same path from a rested drape. What memory is left is the cloth's own: a dress
rests in one of several drapes of the same pose (``benchmarks/experiments/capacity.py repeats`` measures their spread).
"""

from __future__ import annotations

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.rotations import axis_angle_to_matrix, axis_angle_to_quaternion, quaternion_to_axis_angle
from loosefit.motion.heading import heading_angles
from loosefit.motion.motion import Motion
from loosefit.motion.resample import slerp


def hold_poses(motion: Motion, every: int, transition: int, hold: int, in_place: bool = False,
               from_rest: bool = False, order_seed: int | None = None) -> Motion:
    """Every ``every``-th frame of ``motion`` as a key pose: ``transition`` frames moving from the previous
    target (rotations by slerp, root translation linearly; the first target is held throughout), then
    ``hold`` frames standing still at the key.

    Args:
        motion: ``T`` frames.
        every: source frames between key poses (>= 1); keys are frames ``0, every, 2 every, ...``.
        transition: frames moving to a key (>= 1); the last of them is the key itself.
        hold: frames held at the key after it is reached (>= 1).
        in_place: keep the root's horizontal (x, y) position at the first frame's: the body poses on the spot
            instead of covering a walk's stride in each transition, which would swing the cloth for nothing
            (a static garment shape does not depend on where the body stands).
        from_rest: reach every key from the rest pose: first ``transition + hold`` frames going to, then
            holding, the rest pose under the key's root (joints unrotated, the root's rotation reduced to its
            heading about +Z, the key's horizontal root position at the first key's height), then
            ``transition + hold`` frames to the key as above.
        order_seed: visit the keys in a random order drawn with this seed (None: in the motion's order): the same
            poses reached along other paths, whose drapes at one pose average to what a function of the pose can
            know (``in_place`` and the rests' height then follow the first key visited).

    Returns:
        A Motion of ``K * B`` frames at the source's frame rate, ``K = ceil(T / every)`` keys of ``B =
        transition + hold`` frames each (``2 * (transition + hold)`` with ``from_rest``).
    """
    for name, value in (("every", every), ("transition", transition), ("hold", hold)):
        if not (isinstance(value, (int, np.integer)) and value >= 1):
            raise InputError(f"hold_poses: {name!r} must be an integer >= 1, got {value!r}")
    if order_seed is not None and not (isinstance(order_seed, (int, np.integer)) and order_seed >= 0):
        raise InputError(f"hold_poses: 'order_seed' must be None or an integer >= 0, got {order_seed!r}")
    keys = np.arange(0, motion.num_frames, every)
    if order_seed is not None:
        keys = np.random.default_rng(order_seed).permutation(keys)
    q = axis_angle_to_quaternion(torch.from_numpy(motion.rotations[keys].astype(np.float64))).numpy()
    t = motion.translation[keys].astype(np.float64)
    if in_place:
        t[:, :2] = t[0, :2]
    if from_rest:  # the targets alternate: rest under key 0, key 0, rest under key 1, key 1, ...
        q = np.stack([rest_under(q, motion.rotations[keys, 0]), q], axis=1).reshape(-1, *q.shape[1:])
        t = np.repeat(t, 2, axis=0)
        t[0::2, 2] = t[0, 2]  # every rest at one height: a walk's bounce would lift the rested drape by cm
    previous = np.concatenate([q[:1], q[:-1]])  # (targets, J, 4): the first moves from itself
    previous_t = np.concatenate([t[:1], t[:-1]])
    a = np.concatenate([np.arange(1, transition + 1) / transition, np.ones(hold)])  # (B,) fraction of the way
    quats = slerp(previous[:, None], q[:, None], a[None, :, None, None])  # (K, B, J, 4)
    trans = previous_t[:, None] + a[None, :, None] * (t - previous_t)[:, None]  # (K, B, 3)
    count = quats.shape[0] * quats.shape[1]
    rotations = quaternion_to_axis_angle(torch.from_numpy(quats.reshape(count, -1, 4))).numpy()
    name = (f"{motion.name} (key every {every}, {transition} + {hold} frames{', in place' if in_place else ''}"
            f"{', from rest' if from_rest else ''}{'' if order_seed is None else f', order {order_seed}'})")
    return Motion(rotations, trans.reshape(count, 3), motion.fps, motion.rig, motion.joint_names, name)


def rest_under(keys: np.ndarray, root_rotations: np.ndarray) -> np.ndarray:
    """The rest pose under each key: quaternions ``(K, J, 4)`` (w, x, y, z) of every joint unrotated but the
    root, turned about +Z to the heading of ``root_rotations`` (``(K, 3)`` axis-angle)."""
    root = axis_angle_to_matrix(torch.from_numpy(root_rotations.astype(np.float64))).numpy()
    psi = heading_angles(root)
    rest = np.zeros_like(keys)
    rest[..., 0] = 1.0
    rest[:, 0] = np.stack([np.cos(psi / 2), np.zeros_like(psi), np.zeros_like(psi), np.sin(psi / 2)], axis=1)
    return rest


def settled_frames(num_frames: int, transition: int, hold: int, from_rest: bool = False) -> np.ndarray:
    """Indices of the settled frames (the last held frame of every key) of a :func:`hold_poses` result of
    ``num_frames`` frames."""
    block = (transition + hold) * (2 if from_rest else 1)
    return np.arange(block - 1, num_frames, block)
