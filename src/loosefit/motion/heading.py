"""The heading frame of a motion's frames: where the body stands and which way it faces, without its tilt.

Frame ``t``'s heading frame has its origin under the root joint on the floor plane and is rotated about Z by
the root's heading (yaw) ``psi_t``, so that in it the body faces -Y, as at rest::

    F_t = [Rz(psi_t) | (x_t, y_t, 0)]          canonical point  p_c = Rz(psi_t)^T (p - (x_t, y_t, 0))

The garment networks see the body and predict the garment in it (:mod:`loosefit.models.motion_features`);
key poses are turned by it (:mod:`loosefit.motion.hold`).

A per-garment network may instead predict the garment in one of two frames that follow the root joint (``frame`` in
its model config, ours; :data:`FRAMES` names all three, :func:`motion_frames` gives each):

- ``raised``: the heading frame raised to the root joint, ``[Rz(psi_t) | p_root]``: a crouch or a jump carries the
  garment down or up with the hips, where in the heading frame the network has to learn it from the root height;
- ``pelvis``: the root joint's whole frame ``[R_root | p_root]``: a body that leans or bends over carries its
  garment with it too.

Which fits a garment best with no learning at all is measured by the mean canonical garment of the training frames
(``benchmarks/experiments/garment_frames.py``).
"""

from __future__ import annotations

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion.motion import Motion

#: The body's forward direction at rest (Anny and every loosefit body face -Y).
FORWARD = np.array([0.0, -1.0, 0.0])

#: The frames a garment network may predict in (module doc).
FRAMES = ("heading", "raised", "pelvis")


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


def check_frame(frame: str) -> None:
    """Refuse a frame that is not one of :data:`FRAMES` (a config's ``frame``)."""
    if frame not in FRAMES:
        raise InputError(f"frame must be one of {FRAMES}, got {frame!r}")


def garment_frames(root_rotations: np.ndarray, translation: np.ndarray, frame: str = "heading"):
    """The frames ``frame`` (one of :data:`FRAMES`) of root rotations ``(T, 3)`` axis-angle and root positions
    ``translation (T, 3)`` metres: rotations ``(T, 3, 3)`` float64 and origins ``(T, 3)`` float64 (the heading
    frame's on the floor, z = 0; the others' at the root joint)."""
    check_frame(frame)
    root_rot = axis_angle_to_matrix(torch.from_numpy(np.asarray(root_rotations)).double()).numpy()
    origin = np.asarray(translation, np.float64).copy()
    if frame == "pelvis":
        return root_rot, origin
    if frame == "heading":
        origin[:, 2] = 0.0
    return rot_z(heading_angles(root_rot)), origin


def motion_frames(motion: Motion, frame: str = "heading") -> tuple[np.ndarray, np.ndarray]:
    """The frames ``frame`` of a motion (:func:`garment_frames`): rotations ``(T, 3, 3)``, origins ``(T, 3)``."""
    return garment_frames(motion.rotations[:, 0], motion.translation, frame)


def heading_frames(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """Heading frames of a motion: rotations ``(T, 3, 3)`` float64 and origins ``(T, 3)`` (z = 0)."""
    return motion_frames(motion, "heading")


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
