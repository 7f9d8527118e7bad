"""A motion at another frame rate: rotations by quaternion slerp, translation linearly."""

from __future__ import annotations

import numpy as np
import torch

from loosefit.geometry.rotations import axis_angle_to_quaternion, quaternion_to_axis_angle
from loosefit.motion.motion import Motion


def resample(motion: Motion, fps: float) -> Motion:
    """``motion`` at another frame rate: rotations by quaternion slerp, translation linearly.

    Output frame ``k`` is at time ``k / fps``; frames cover the source's time span ``[0, (T - 1) / fps_in]``.
    """
    if abs(motion.fps - fps) < 1e-9 * fps:
        return motion
    q = axis_angle_to_quaternion(torch.from_numpy(motion.rotations.astype(np.float64))).numpy()
    q, translation = resample_quaternions(q, motion.translation.astype(np.float64), motion.fps, fps)
    rotations = quaternion_to_axis_angle(torch.from_numpy(q)).numpy()
    return Motion(rotations, translation, fps, motion.rig, motion.joint_names, motion.name)


def slow_down(motion: Motion, factor: float) -> Motion:
    """``motion`` played ``factor`` times slower at its own frame rate (``factor`` > 1: slower).

    Output frame ``k`` is the source at time ``k / (factor * fps)``; the result has ``floor((T - 1) * factor) + 1``
    frames, so every ``factor``-th frame of an integer factor is a source frame exactly. A quasi-static
    version of a motion: the cloth's inertial forces fall as ``1 / factor^2``.
    """
    if not factor > 0:
        raise ValueError(f"slow-down factor must be positive, got {factor}")
    slowed = resample(motion, motion.fps * factor)
    return Motion(slowed.rotations, slowed.translation, motion.fps, motion.rig, motion.joint_names, motion.name)


def resample_quaternions(q: np.ndarray, translation: np.ndarray, fps_in: float, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Quaternions ``(T, J, 4)`` and translations ``(T, 3)`` at ``fps_in`` -> the same at ``fps``."""
    T = q.shape[0]
    count = int(np.floor((T - 1) / fps_in * fps + 1e-6)) + 1
    at = np.arange(count) * (fps_in / fps)
    i0 = np.minimum(np.floor(at + 1e-6).astype(np.int64), T - 1)
    i1 = np.minimum(i0 + 1, T - 1)
    a = np.clip(at - i0, 0.0, 1.0)[:, None, None]
    translation = (1 - a[:, 0]) * translation[i0] + a[:, 0] * translation[i1]
    return slerp(q[i0], q[i1], a), translation


def slerp(q0: np.ndarray, q1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Spherical interpolation of unit quaternions ``(..., 4)`` at fractions ``a`` (broadcast to ``(..., 1)``),
    along the shorter arc."""
    # q and -q are the same rotation.
    dot = (q0 * q1).sum(-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    omega = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))
    sin = np.sin(omega)
    tiny = sin < 1e-6
    safe = np.where(tiny, 1.0, sin)
    w0 = np.where(tiny, 1 - a, np.sin((1 - a) * omega) / safe)
    w1 = np.where(tiny, a, np.sin(a * omega) / safe)
    return w0 * q0 + w1 * q1

