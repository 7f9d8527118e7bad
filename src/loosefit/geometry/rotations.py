"""Rotation conversions between axis-angle, rotation matrices, quaternions, Euler angles and 6D.

All functions take and return torch tensors with arbitrary leading batch dimensions and work in
float32 or float64. Conventions:

- axis-angle ``(..., 3)``: unit axis times angle in radians.
- matrices ``(..., 3, 3)`` act on column vectors (``x' = R x``).
- quaternions ``(..., 4)`` are ``(w, x, y, z)``.
- Euler angles ``(..., 3)`` in radians for an ``order`` such as ``"xyz"``: *intrinsic* rotations,
  ``R = R_order[0](a0) @ R_order[1](a1) @ R_order[2](a2)`` (BVH channel order).
- 6D ``(..., 6)``: the first two columns of the matrix (Zhou et al. 2019), concatenated.

Besides conversions: the smallest rotation between two directions (:func:`rotation_between`), the
rotation nearest a 3x3 matrix (:func:`nearest_rotation`) and the angle of a rotation
(:func:`rotation_angle`). NumPy arrays are accepted wherever tensors are.
"""

from __future__ import annotations

import numpy as np
import torch

_EPS = 1e-8


def _as_tensor(x) -> torch.Tensor:
    return x if isinstance(x, torch.Tensor) else torch.as_tensor(np.asarray(x))


def skew(v: torch.Tensor) -> torch.Tensor:
    """Cross-product matrices ``(..., 3, 3)`` of vectors ``v: (..., 3)``."""
    zero = torch.zeros_like(v[..., 0])
    x, y, z = v.unbind(-1)
    return torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(v.shape[:-1] + (3, 3))


def axis_angle_to_matrix(aa) -> torch.Tensor:
    """Rodrigues' formula: ``aa: (..., 3)`` -> ``(..., 3, 3)``; exact near zero via Taylor terms."""
    aa = _as_tensor(aa)
    theta2 = (aa * aa).sum(-1, keepdim=True)[..., None]  # (..., 1, 1)
    theta = theta2.clamp_min(0).sqrt()
    small = theta < 1e-4
    safe = torch.where(small, torch.ones_like(theta), theta)
    a = torch.where(small, 1 - theta2 / 6, torch.sin(safe) / safe)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(safe)) / (safe * safe))
    K = skew(aa)
    eye = torch.eye(3, dtype=aa.dtype, device=aa.device).expand(K.shape)
    return eye + a * K + b * (K @ K)


def matrix_to_quaternion(R) -> torch.Tensor:
    """``(..., 3, 3)`` -> unit quaternions ``(..., 4)`` (w, x, y, z) with ``w >= 0``; stable for all angles."""
    R = _as_tensor(R)
    m = R
    t = torch.stack(
        [
            1 + m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2],
            1 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2],
            1 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2],
            1 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2],
        ],
        -1,
    )
    # Four candidate quaternions, each well conditioned when its own component is large.
    cands = torch.stack(
        [
            torch.stack([t[..., 0], m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1),
            torch.stack([m[..., 2, 1] - m[..., 1, 2], t[..., 1], m[..., 1, 0] + m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0]], -1),
            torch.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] + m[..., 0, 1], t[..., 2], m[..., 2, 1] + m[..., 1, 2]], -1),
            torch.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 2, 1] + m[..., 1, 2], t[..., 3]], -1),
        ],
        -2,
    )
    best = t.argmax(-1)
    q = torch.gather(cands, -2, best[..., None, None].expand(best.shape + (1, 4))).squeeze(-2)
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(_EPS)
    return torch.where(q[..., :1] < 0, -q, q)


def quaternion_to_matrix(q) -> torch.Tensor:
    """Quaternions ``(..., 4)`` (w, x, y, z), normalised first -> ``(..., 3, 3)``."""
    q = _as_tensor(q)
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(_EPS)
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        -1,
    ).reshape(q.shape[:-1] + (3, 3))


def quaternion_to_axis_angle(q) -> torch.Tensor:
    """Quaternions ``(..., 4)`` -> axis-angle ``(..., 3)`` with angle in ``[0, pi]``."""
    q = _as_tensor(q)
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(_EPS)
    q = torch.where(q[..., :1] < 0, -q, q)
    v = q[..., 1:]
    s = v.norm(dim=-1, keepdim=True)
    angle = 2 * torch.atan2(s, q[..., :1])
    small = s < 1e-6
    scale = torch.where(small, 2.0 / q[..., :1].clamp_min(_EPS), angle / torch.where(small, torch.ones_like(s), s))
    return v * scale


def axis_angle_to_quaternion(aa) -> torch.Tensor:
    """Axis-angle ``(..., 3)`` -> quaternions ``(..., 4)`` (w, x, y, z)."""
    aa = _as_tensor(aa)
    angle = aa.norm(dim=-1, keepdim=True)
    half = angle / 2
    small = angle < 1e-6
    k = torch.where(small, 0.5 - angle * angle / 48, torch.sin(half) / torch.where(small, torch.ones_like(angle), angle))
    return torch.cat([torch.cos(half), aa * k], -1)


def matrix_to_axis_angle(R) -> torch.Tensor:
    """``(..., 3, 3)`` -> axis-angle ``(..., 3)``; robust at 0 and pi through quaternions."""
    return quaternion_to_axis_angle(matrix_to_quaternion(R))


def _axis_matrix(axis: str, angle: torch.Tensor) -> torch.Tensor:
    c, s = torch.cos(angle), torch.sin(angle)
    one, zero = torch.ones_like(angle), torch.zeros_like(angle)
    rows = {
        "x": [one, zero, zero, zero, c, -s, zero, s, c],
        "y": [c, zero, s, zero, one, zero, -s, zero, c],
        "z": [c, -s, zero, s, c, zero, zero, zero, one],
    }[axis]
    return torch.stack(rows, -1).reshape(angle.shape + (3, 3))


def euler_to_matrix(angles, order: str = "xyz") -> torch.Tensor:
    """Intrinsic Euler angles ``(..., 3)`` in radians -> ``(..., 3, 3)``; ``order`` like ``"zxy"``."""
    angles = _as_tensor(angles)
    order = order.lower()
    if sorted(order) != ["x", "y", "z"]:
        raise ValueError(f"Euler order must be a permutation of 'xyz', got {order!r}")
    R = _axis_matrix(order[0], angles[..., 0])
    for i in (1, 2):
        R = R @ _axis_matrix(order[i], angles[..., i])
    return R


def matrix_to_euler(R, order: str = "xyz") -> torch.Tensor:
    """Inverse of :func:`euler_to_matrix` for permutations of 'xyz' (Tait-Bryan angles).

    The middle angle lies in ``[-pi/2, pi/2]``; at gimbal lock the third angle is set to zero.
    """
    R = _as_tensor(R)
    order = order.lower()
    idx = {"x": 0, "y": 1, "z": 2}
    i, j, k = (idx[c] for c in order)
    # Sign of the permutation decides the signs in the closed form.
    sign = 1.0 if (j - i) % 3 == 1 else -1.0
    mid = torch.asin((sign * R[..., i, k]).clamp(-1, 1))
    first = torch.atan2(-sign * R[..., j, k], R[..., k, k])
    third = torch.atan2(-sign * R[..., i, j], R[..., i, i])
    locked = (R[..., i, k].abs() > 1 - 1e-6)
    if locked.any():
        # Gimbal lock: put all of the remaining rotation into the first angle.
        first_locked = torch.atan2(sign * R[..., k, j], R[..., j, j])
        first = torch.where(locked, first_locked, first)
        third = torch.where(locked, torch.zeros_like(third), third)
    return torch.stack([first, mid, third], -1)


def matrix_to_sixd(R) -> torch.Tensor:
    """``(..., 3, 3)`` -> 6D representation ``(..., 6)``: first column then second column."""
    R = _as_tensor(R)
    return torch.cat([R[..., :, 0], R[..., :, 1]], -1)


def sixd_to_matrix(d6) -> torch.Tensor:
    """6D ``(..., 6)`` -> rotation ``(..., 3, 3)`` by Gram-Schmidt (any 6D input gives a rotation)."""
    d6 = _as_tensor(d6)
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = a1 / a1.norm(dim=-1, keepdim=True).clamp_min(_EPS)
    a2 = a2 - (b1 * a2).sum(-1, keepdim=True) * b1
    b2 = a2 / a2.norm(dim=-1, keepdim=True).clamp_min(_EPS)
    b3 = torch.cross(b1, b2, dim=-1)
    return torch.stack([b1, b2, b3], -1)


def rotation_between(a, b) -> torch.Tensor:
    """The smallest rotation taking unit vectors ``a`` to ``b`` (both ``(..., 3)``, broadcast) -> ``(..., 3, 3)``.

    For opposite vectors (a half turn about any axis perpendicular to ``a``) the axis is ``a``
    crossed with the coordinate axis ``a`` is least aligned with.
    """
    a, b = torch.broadcast_tensors(_as_tensor(a), _as_tensor(b))
    axis = torch.cross(a, b, dim=-1)
    s = axis.norm(dim=-1)
    c = (a * b).sum(-1)
    helper = torch.eye(3, dtype=a.dtype, device=a.device)[a.abs().argmin(-1)]
    axis = torch.where((s < 1e-9)[..., None], torch.cross(a, helper, dim=-1), axis)
    axis = axis / axis.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return axis_angle_to_matrix(axis * torch.atan2(s, c)[..., None])


def nearest_rotation(M) -> torch.Tensor:
    """The rotation nearest ``M (..., 3, 3)`` in the Frobenius norm (by SVD, reflections excluded):
    e.g. the chordal mean of rotations from their sum."""
    M = _as_tensor(M)
    U, _, Vt = torch.linalg.svd(M)
    D = torch.ones(M.shape[:-1], dtype=M.dtype, device=M.device)
    D[..., -1] = torch.sign(torch.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt


def rotation_angle(R) -> torch.Tensor:
    """Rotation angles ``(...)`` in radians, in ``[0, pi]``, of rotations ``R (..., 3, 3)``."""
    R = _as_tensor(R)
    trace = R.diagonal(dim1=-2, dim2=-1).sum(-1)
    return torch.arccos(((trace - 1) / 2).clamp(-1.0, 1.0))


def rigid(R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Homogeneous transforms ``(..., 4, 4)`` from rotations ``(..., 3, 3)`` and translations ``(..., 3)``."""
    T = torch.zeros(R.shape[:-2] + (4, 4), dtype=R.dtype, device=R.device)
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1
    return T
