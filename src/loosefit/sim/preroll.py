"""The pre-roll: the body moves from the rest pose into a motion's first frame while the cloth settles.

The pre-roll starts from the rest pose placed under the first frame's root and turned to its
heading (a rigid move, so the garment starts undeformed). Joint rotations, the root orientation
and the root translation then ease into the first frame (smoothstep, along rotation geodesics)
over the first two thirds of the pre-roll; the last third holds the first frame so that the
cloth comes to rest.
"""

from __future__ import annotations

import numpy as np
import torch

from loosefit.body.base import BodyModel
from loosefit.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from loosefit.motion.motion import Motion

#: Fraction of the pre-roll spent blending; the rest holds the first frame.
BLEND_FRACTION = 2.0 / 3.0


def preroll_frames(seconds: float, fps: float) -> int:
    """Number of pre-roll frames for ``seconds`` at ``fps``."""
    return int(round(seconds * fps))


def start_pose(body: BodyModel, motion: Motion, shape=None) -> tuple[np.ndarray, np.ndarray]:
    """Root orientation and translation of the pre-roll's first frame.

    Returns:
        ``(root_rotation (3,) axis-angle, a rotation about +Z: the heading of the motion's first
        frame; translation (3,): the first frame's horizontal root position at rest height)``.
    """
    R0 = axis_angle_to_matrix(torch.from_numpy(motion.rotations[0, 0]).double()).numpy()
    heading = np.arctan2(R0[1, 0], R0[0, 0])  # where the root's +X axis points, seen from above
    translation = motion.translation[0].astype(np.float32).copy()
    translation[2] = body.rest_root_position(shape)[2]
    return np.array([0.0, 0.0, heading], np.float32), translation


def with_preroll(body: BodyModel, motion: Motion, frames: int, shape=None) -> Motion:
    """``motion`` preceded by ``frames`` pre-roll frames (``frames + T`` in all)."""
    if frames == 0:
        return motion
    blend = max(1, int(round(frames * BLEND_FRACTION)))
    u = np.clip(np.arange(frames, dtype=np.float64) / blend, 0.0, 1.0)
    s = u * u * (3.0 - 2.0 * u)  # smoothstep: zero velocity at both ends
    root0, trans0 = start_pose(body, motion, shape)
    # Non-root joints start at identity: scaling the axis-angle is the geodesic from identity.
    rotations = s[:, None, None] * motion.rotations[:1].astype(np.float64)
    # Root: geodesic from the heading-only start orientation H to the first frame's R0.
    H = axis_angle_to_matrix(torch.from_numpy(root0).double())
    R0 = axis_angle_to_matrix(torch.from_numpy(motion.rotations[0, 0]).double())
    step = matrix_to_axis_angle(H.T @ R0)
    Rs = H @ axis_angle_to_matrix(torch.from_numpy(s)[:, None] * step[None])
    rotations[:, 0] = matrix_to_axis_angle(Rs).numpy()
    translation = trans0[None] + s[:, None] * (motion.translation[:1] - trans0[None])
    return Motion(
        rotations=np.concatenate([rotations.astype(np.float32), motion.rotations]),
        translation=np.concatenate([translation.astype(np.float32), motion.translation]),
        fps=motion.fps,
        rig=motion.rig,
        joint_names=motion.joint_names,
        name=motion.name,
    )


def morph_frames(source: np.ndarray, target: np.ndarray, morph: int, settle: int) -> tuple[np.ndarray, np.ndarray]:
    """A body changing shape in place: its vertices ``source (V, 3)`` move linearly to ``target (V, 3)``
    over ``morph`` frames, then hold for ``settle`` frames (the cloth comes to rest on the new shape).

    Returns:
        ``(frames (1 + morph + settle, V, 3) float32, weight (1 + morph + settle,) float64)``: frame 0 is
        ``source``; ``weight`` is the share of the change done at each frame (0 at frame 0, 1 from frame
        ``morph`` on), so that anything carried by the body change follows it in step.
    """
    weight = np.clip(np.arange(1 + morph + settle, dtype=np.float64) / max(morph, 1), 0.0, 1.0)
    source, target = np.asarray(source, np.float64), np.asarray(target, np.float64)
    frames = source[None] + weight[:, None, None] * (target - source)[None]
    return frames.astype(np.float32), weight
