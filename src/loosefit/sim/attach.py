"""The garment skinned to the body: where its pinned vertices (waistband, shoulders) go in every frame.

Each garment vertex takes the skinning weights of its nearest rest-pose body vertex and is posed
by linear blend skinning with the body's joint transforms. The simulator uses these positions
as the animated targets of pinned vertices (and as the cloth's start state); the whole garment posed
so is the body-LBS baseline of the benchmarks (:func:`body_lbs`).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

from loosefit.body.base import BodyModel
from loosefit.geometry.lbs import forward_kinematics, linear_blend_skinning, skinning_transforms
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.motion.motion import Motion


def garment_weights(garment_verts: np.ndarray, body: BodyModel, shape=None) -> np.ndarray:
    """``(V, J)`` float32 skinning weights of garment vertices ``(V, 3)``: those of the nearest body vertex."""
    _, nearest = cKDTree(body.rest_verts(shape)).query(np.asarray(garment_verts, np.float64))
    return body.skinning_weights()[nearest]


def skin_garment(
    garment_verts: np.ndarray, weights: np.ndarray, body: BodyModel, motion: Motion, shape=None
) -> np.ndarray:
    """Pose rest garment vertices ``(V, 3)`` along ``motion`` (``T`` frames) with ``weights (V, J)``.

    Returns:
        ``(T, V, 3)`` float32 positions, metres.
    """
    body.check_motion(motion)
    rest_joints = torch.from_numpy(body.rest_joints(shape))
    with torch.no_grad():
        world = forward_kinematics(
            axis_angle_to_matrix(torch.from_numpy(motion.rotations)),
            torch.from_numpy(motion.translation),
            rest_joints,
            body.parents,
        )
        verts = linear_blend_skinning(
            torch.from_numpy(np.asarray(garment_verts, np.float32)),
            torch.from_numpy(np.asarray(weights, np.float32)),
            skinning_transforms(world, rest_joints),
        )
    return verts.numpy().astype(np.float32)


def body_lbs(garment_verts: np.ndarray, body: BodyModel, motion: Motion, shape=None) -> np.ndarray:
    """The body-LBS baseline: every vertex of a rest garment ``(V, 3)`` skinned along ``motion`` with the weights
    of its nearest rest body vertex (:func:`garment_weights`, :func:`skin_garment`); ``(T, V, 3)`` float32,
    metres, in the world. The same as a trained :class:`~loosefit.models.body_lbs.BodyLBS` run, without one."""
    return skin_garment(garment_verts, garment_weights(garment_verts, body, shape), body, motion, shape)
