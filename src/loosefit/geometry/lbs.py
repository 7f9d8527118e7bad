"""Forward kinematics and linear blend skinning (batched, torch).

Rig convention used throughout loosefit (the SMPL convention): in the rest pose every joint frame
is aligned with the world axes. A joint's local rotation ``R_j`` rotates its subtree about the joint
position, expressed in world-aligned axes at rest. The root's rotation is the global orientation
and ``root_translation`` is the world position of the root joint.
"""

from __future__ import annotations

import numpy as np
import torch

from loosefit.geometry.rotations import axis_angle_to_matrix, rigid


def topological_order(parents: np.ndarray) -> np.ndarray:
    """Joint indices ordered so that every parent comes before its children. ``parents: (J,)``, -1 = root."""
    parents = np.asarray(parents)
    depth = np.zeros(len(parents), dtype=np.int64)
    for j in range(len(parents)):
        p, d = parents[j], 0
        while p >= 0:
            d += 1
            p = parents[p]
            if d > len(parents):
                raise ValueError("joint parents contain a cycle")
        depth[j] = d
    return np.argsort(depth, kind="stable")


def forward_kinematics(
    local_rot: torch.Tensor, root_translation: torch.Tensor, rest_joints: torch.Tensor, parents
) -> torch.Tensor:
    """World joint transforms from local rotations.

    Args:
        local_rot: ``(T, J, 3, 3)`` local joint rotations (world-aligned at rest).
        root_translation: ``(T, 3)`` world position of the root joint, metres.
        rest_joints: ``(J, 3)`` rest joint positions, metres.
        parents: ``(J,)`` parent index per joint, -1 for the root.

    Returns:
        ``(T, J, 4, 4)`` world transforms ``G_j = [W_j | p_j]``: accumulated rotation and posed joint position.
    """
    parents = np.asarray(parents)
    T, J = local_rot.shape[:2]
    world_R = [None] * J
    world_p = [None] * J
    for j in topological_order(parents):
        p = parents[j]
        if p < 0:
            world_R[j] = local_rot[:, j]
            world_p[j] = root_translation
        else:
            offset = rest_joints[j] - rest_joints[p]
            world_R[j] = world_R[p] @ local_rot[:, j]
            world_p[j] = world_p[p] + (world_R[p] @ offset)
    return rigid(torch.stack(world_R, 1), torch.stack(world_p, 1))


def skinning_transforms(world: torch.Tensor, rest_joints: torch.Tensor) -> torch.Tensor:
    """``(T, J, 4, 4)`` transforms taking rest-pose points to posed points: ``G_j [I | -rest_j]``."""
    A = world.clone()
    A[..., :3, 3] = world[..., :3, 3] - (world[..., :3, :3] @ rest_joints[..., None])[..., 0]
    return A


def linear_blend_skinning(rest_verts: torch.Tensor, weights: torch.Tensor, transforms: torch.Tensor) -> torch.Tensor:
    """Linear blend skinning.

    Args:
        rest_verts: ``(V, 3)`` or ``(T, V, 3)`` rest positions.
        weights: ``(V, J)`` skinning weights (rows sum to 1), dense.
        transforms: ``(T, J, 4, 4)`` skinning transforms (see :func:`skinning_transforms`).

    Returns:
        ``(T, V, 3)`` skinned positions.
    """
    blend = torch.einsum("vj,tjab->tvab", weights, transforms[..., :3, :])  # (T, V, 3, 4)
    if rest_verts.dim() == 2:
        rest_verts = rest_verts.expand(transforms.shape[0], -1, -1)
    return (blend[..., :3] @ rest_verts[..., None])[..., 0] + blend[..., 3]


def pose_skeleton_and_skin(
    rotations, root_translation, rest_joints, parents, rest_verts, weights
) -> tuple[torch.Tensor, torch.Tensor]:
    """Convenience: axis-angle ``(T, J, 3)`` + ``(T, 3)`` -> (verts ``(T, V, 3)``, world ``(T, J, 4, 4)``)."""
    R = axis_angle_to_matrix(rotations)
    world = forward_kinematics(R, root_translation, rest_joints, parents)
    verts = linear_blend_skinning(rest_verts, weights, skinning_transforms(world, rest_joints))
    return verts, world
