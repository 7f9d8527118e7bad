"""Loss terms shared by the garment models (torch, differentiable).

Shapes: ``pred``/``target`` ``(B, T, V, 3)`` metres; ``mask`` ``(B, T)`` float, 1 where a frame counts
(0 for burn-in frames of truncated back-propagation through time). Every term averages over the
counted frames, so values do not depend on the batch or window size.
"""

from __future__ import annotations

import numpy as np
import torch

from loosefit.geometry.laplacian import uniform_laplacian
from loosefit.geometry.normals import face_normals_torch


def frame_mask(burn_in: torch.Tensor, frames: int) -> torch.Tensor:
    """``(B, T)`` mask with zeros on each window's first ``burn_in[b]`` frames. ``burn_in: (B,)`` int."""
    t = torch.arange(frames, device=burn_in.device)
    return (t[None] >= burn_in[:, None]).float()


def _masked_mean(per_frame: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean of ``per_frame (B, T)`` over frames where ``mask`` is 1."""
    if mask is None:
        return per_frame.mean()
    return (per_frame * mask).sum() / mask.sum().clamp_min(1.0)


def masked_errors_mm(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> dict[str, float]:
    """The validation errors of every method, millimetres: ``rmse_mm`` (the root of the mean squared
    vertex distance) and ``mean_vertex_error_mm`` over the frames where ``mask (B, T)`` is 1.

    ``pred``, ``target``: ``(B, T, V, 3)`` metres with a mask, or any ``(..., V, 3)`` without one (every
    frame counts). Per frame the squared distances and the distances are averaged over the vertices
    first, then over the counted frames (all frames have the same vertex count).
    """
    err = pred - target
    sq, dist = (err**2).sum(-1).mean(-1), err.norm(dim=-1).mean(-1)
    if mask is None:
        return {"rmse_mm": float(sq.mean().sqrt() * 1e3), "mean_vertex_error_mm": float(dist.mean() * 1e3)}
    n = mask.sum().clamp_min(1)
    return {"rmse_mm": float(((sq * mask).sum() / n).sqrt() * 1e3),
            "mean_vertex_error_mm": float((dist * mask).sum() / n * 1e3)}


def vertex_distance(pred, target, mask=None) -> torch.Tensor:
    """Mean per-vertex Euclidean distance, metres (VirtualBones' vertex term)."""
    return _masked_mean((pred - target).norm(dim=-1).mean(-1), mask)


def vertex_l1(pred, target, mask=None) -> torch.Tensor:
    """Mean absolute coordinate error, metres (JointNet's L_cloth, per coordinate)."""
    return _masked_mean((pred - target).abs().mean((-1, -2)), mask)


def laplacian_operator(faces: np.ndarray, num_verts: int) -> torch.Tensor:
    """The uniform graph Laplacian ``(V, V)`` as a sparse torch tensor (float32)."""
    L = uniform_laplacian(faces, num_verts).tocoo()
    idx = torch.from_numpy(np.vstack([L.row, L.col]).astype(np.int64))
    return torch.sparse_coo_tensor(idx, torch.from_numpy(L.data.astype(np.float32)), (num_verts, num_verts), check_invariants=True).coalesce()


def apply_laplacian(L: torch.Tensor, verts: torch.Tensor) -> torch.Tensor:
    """``L @ verts`` for ``verts (..., V, 3)``."""
    shape = verts.shape
    flat = verts.reshape(-1, shape[-2], 3).permute(1, 0, 2).reshape(shape[-2], -1)
    out = torch.sparse.mm(L, flat)
    return out.reshape(shape[-2], -1, 3).permute(1, 0, 2).reshape(shape)


def laplacian_difference(pred, target, L: torch.Tensor, mask=None) -> torch.Tensor:
    """Mean per-vertex distance between the Laplacian coordinates of ``pred`` and ``target`` (VirtualBones Eq. 2)."""
    return vertex_distance(apply_laplacian(L, pred), apply_laplacian(L, target), mask)


def normal_loss(pred, target, faces: torch.Tensor, mask=None) -> torch.Tensor:
    """Mean ``1 - cos`` between predicted and target face normals (JointNet's L_norm)."""
    cos = (face_normals_torch(pred, faces) * face_normals_torch(target, faces)).sum(-1)
    return _masked_mean((1 - cos).mean(-1), mask)


def collision_loss(pred, body, body_normals, nearest, margin: float = 0.0, mask=None) -> torch.Tensor:
    """Penetration penalty ``max(margin - n_k . (v_i - b_k), 0)`` averaged over vertices (VirtualBones Sec. 4.3).

    ``body``/``body_normals`` ``(B, T, Vb, 3)``; ``nearest`` ``(B, T, V)`` int64: index of the body vertex
    nearest to each ground-truth garment vertex (precomputed: the prediction stays close to it).
    """
    idx = nearest[..., None].expand(-1, -1, -1, 3)
    b = torch.gather(body, 2, idx)
    n = torch.gather(body_normals, 2, idx)
    depth = margin - ((pred - b) * n).sum(-1)
    return _masked_mean(torch.relu(depth).mean(-1), mask)
