"""The heading frame of a motion's frames: where the body stands and which way it faces, without its tilt.

Frame ``t``'s heading frame has its origin under the root joint on the floor plane and is rotated about Z by
the root's heading (yaw) ``psi_t``, so that in it the body faces -Y, as at rest::

    F_t = [Rz(psi_t) | (x_t, y_t, 0)]          canonical point  p_c = Rz(psi_t)^T (p - (x_t, y_t, 0))

The garment networks see the body and predict the garment in it (:mod:`loosefit.models.motion_features`);
key poses are turned by it (:mod:`loosefit.motion.hold`).
"""

from __future__ import annotations

import numpy as np
import torch

from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion.motion import Motion

#: The body's forward direction at rest (Anny and every loosefit body face -Y).
FORWARD = np.array([0.0, -1.0, 0.0])


def heading_angles(root_rot: np.ndarray) -> np.ndarray:
    """Heading ``psi (T,)`` radians of root rotations ``(T, 3, 3)``: the rotation about Z that takes the
    rest forward (-Y) to the horizontal projection of the rotated forward direction."""
    fwd = root_rot @ FORWARD
    return np.arctan2(fwd[:, 0], -fwd[:, 1])


def rot_z(psi: np.ndarray) -> np.ndarray:
    """``(T, 3, 3)`` rotations about Z by ``psi (T,)``."""
    c, s = np.cos(psi), np.sin(psi)
    R = np.zeros(psi.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1
    return R


def heading_frames(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """Heading frames of a motion: rotations ``(T, 3, 3)`` float64 and origins ``(T, 3)`` (z = 0)."""
    root_rot = axis_angle_to_matrix(torch.from_numpy(motion.rotations[:, 0]).double()).numpy()
    origin = motion.translation.astype(np.float64).copy()
    origin[:, 2] = 0.0
    return rot_z(heading_angles(root_rot)), origin


def to_canonical(points: np.ndarray, rot: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """World points ``(T, N, 3)`` -> canonical ``(T, N, 3)`` float32 with frames ``rot (T,3,3)``, ``origin (T,3)``."""
    return ((points - origin[:, None]) @ rot).astype(np.float32)  # p R == (R^T p^T)^T


def to_world(points, rot, origin):
    """Canonical points ``(T, N, 3)`` -> world; numpy or torch (then ``rot``/``origin`` may be numpy)."""
    if isinstance(points, torch.Tensor):
        rot = torch.as_tensor(rot, dtype=points.dtype, device=points.device)
        origin = torch.as_tensor(origin, dtype=points.dtype, device=points.device)
        return points @ rot.transpose(-1, -2) + origin[:, None]
    return (points @ rot.transpose(0, 2, 1) + origin[:, None]).astype(np.float32)
