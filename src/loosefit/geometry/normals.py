"""Face areas, face normals and vertex normals, batched over frames: one routine, NumPy and torch front-ends.

Every function accepts ``verts (V, 3)`` or ``(..., V, 3)`` (e.g. ``(T, V, 3)``) with ``faces (F, 3)`` and keeps
the leading dimensions. Normals follow the right-hand rule on the face's vertex order.

The routine is written once (:func:`_face_cross`, :func:`_unit`, :func:`_vertex_sum`) over four array
operations (:class:`_Ops`), given once for NumPy and once for torch:

- NumPy (:func:`face_normals`, :func:`vertex_normals`): checked input, computed in float64, returned as float32;
- torch (:func:`face_normals_torch`, :func:`vertex_normals_torch`): tensors as given (dtype, device),
  differentiable, for losses and network inputs.

A vector shorter than :data:`EPS` is divided by :data:`EPS` instead of its length: a degenerate (zero-area)
triangle, and a vertex in no triangle, get a zero normal, and the gradient stays finite.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np
import scipy.sparse as sp
import torch

from loosefit.errors import InputError
from loosefit.geometry.laplacian import check_mesh

#: Lengths below this are treated as this long when normalising.
EPS = 1e-12
WEIGHTINGS = ("area", "uniform")


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Cross products of ``(..., 3)`` arrays; several times faster than ``np.cross`` on large batches."""
    u0, u1, u2 = u[..., 0], u[..., 1], u[..., 2]
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0], -1)


def vertex_incidence(faces: np.ndarray, num_verts: int) -> sp.csr_matrix:
    """The ``(V, F)`` vertex-face incidence (1 where a face has the vertex), float64: for many frames of one mesh,
    build it once and pass it to :func:`vertex_normals`."""
    faces = np.asarray(faces, np.int64)
    F = len(faces)
    return sp.csr_matrix((np.ones(3 * F), (faces.T.ravel(), np.tile(np.arange(F), 3))), shape=(num_verts, F))


class _Ops(NamedTuple):
    """The array operations of the normal routine, in one array library."""

    #: ``(..., 3), (..., 3) -> (..., 3)`` cross products.
    cross: Callable
    #: ``(..., 3) -> (..., 1)`` Euclidean lengths.
    norm: Callable
    #: ``(x, eps) -> max(x, eps)`` elementwise.
    at_least: Callable
    #: ``(vectors (..., F, 3), faces (F, 3), V) -> (..., V, 3)``: each face's vector added to its three corners,
    #: a vertex's faces summed in increasing face order from zero.
    corner_sum: Callable


def _numpy_corner_sum(vectors: np.ndarray, faces: np.ndarray, V: int, incidence=None) -> np.ndarray:
    # the sparse incidence sums each face's vector onto its three corners for all frames at once
    incidence = vertex_incidence(faces, V) if incidence is None else incidence
    F = vectors.shape[-2]
    flat = np.moveaxis(vectors.reshape((-1, F, 3)), 1, 0).reshape(F, -1)  # (F, batch*3)
    summed = (incidence @ flat).reshape(V, -1, 3)
    return np.moveaxis(summed, 0, 1).reshape(vectors.shape[:-2] + (V, 3))


def _torch_corner_sum(vectors: torch.Tensor, faces: torch.Tensor, V: int) -> torch.Tensor:
    out = vectors.new_zeros(vectors.shape[:-2] + (V, 3))
    return out.index_add_(-2, faces.reshape(-1), vectors.repeat_interleave(3, -2))


_NUMPY = _Ops(cross, lambda v: np.linalg.norm(v, axis=-1, keepdims=True), np.maximum, _numpy_corner_sum)
def _torch_cross(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """``u x v`` over the last axis from its components: twice as fast as ``torch.cross`` on the CPU, backward
    included, for the ``(B, T, F, 3)`` face vectors of a training batch (measured: 4 x 90 x 2,242 faces)."""
    u0, u1, u2 = u.unbind(-1)
    v0, v1, v2 = v.unbind(-1)
    return torch.stack([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0], -1)


_TORCH = _Ops(_torch_cross, lambda v: v.norm(dim=-1, keepdim=True), torch.clamp_min, _torch_corner_sum)


def _face_cross(ops: _Ops, verts, faces):
    """``(..., F, 3)`` cross products ``(b - a) x (c - a)`` per face: direction = normal, length = 2 x area."""
    a, b, c = (verts[..., faces[:, k], :] for k in range(3))
    return ops.cross(b - a, c - a)


def _unit(ops: _Ops, v, eps: float = EPS):
    """``v (..., 3)`` divided by its length (by ``eps`` where shorter)."""
    return v / ops.at_least(ops.norm(v), eps)


def _vertex_sum(ops: _Ops, verts, faces, weighting: str, **corner):
    """``(..., V, 3)``: each vertex's sum of its faces' normals times their areas (``"area"``) or of the unit
    normals (``"uniform"``), each scaled by 2."""
    if weighting not in WEIGHTINGS:
        raise InputError(f"vertex normal weighting must be 'area' or 'uniform', got {weighting!r}")
    vectors = _face_cross(ops, verts, faces)
    if weighting == "uniform":
        vectors = _unit(ops, vectors)
    return ops.corner_sum(vectors, faces, verts.shape[-2], **corner)


# --------------------------------------------------------------------------------------------- NumPy front-end


def face_cross(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unchecked: ``(..., F, 3)`` cross products ``(b - a) x (c - a)`` per face: direction = normal, length = 2 x area."""
    return _face_cross(_NUMPY, verts, faces)


def face_areas(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Triangle areas ``(..., F)`` in m^2."""
    verts, faces = check_mesh(verts, faces)
    return 0.5 * np.linalg.norm(face_cross(np.asarray(verts, np.float64), faces), axis=-1)


def face_normals(verts: np.ndarray, faces: np.ndarray, dtype=np.float32, eps: float = EPS) -> np.ndarray:
    """Unit face normals ``(..., F, 3)`` (``dtype``, float32 by default; computed in float64); zero vectors for
    degenerate (zero-area) triangles. ``eps``: see the module docstring."""
    verts, faces = check_mesh(verts, faces)
    return _unit(_NUMPY, face_cross(np.asarray(verts, np.float64), faces), eps).astype(dtype, copy=False)


def vertex_normals(verts: np.ndarray, faces: np.ndarray, weighting: str = "area",
                   incidence: sp.csr_matrix | None = None) -> np.ndarray:
    """Unit vertex normals ``(..., V, 3)`` float32 (computed in float64): normalised weighted sum of the incident
    face normals.

    ``weighting``: ``"area"`` (face normal times face area, the usual choice for cloth) or ``"uniform"`` (unit
    face normals). Vertices in no triangle get a zero normal. ``incidence``: :func:`vertex_incidence` of these
    faces, when many frames are done one at a time.
    """
    verts, faces = check_mesh(verts, faces)
    summed = _vertex_sum(_NUMPY, np.asarray(verts, np.float64), faces, weighting, incidence=incidence)
    return _unit(_NUMPY, summed).astype(np.float32)


# --------------------------------------------------------------------------------------------- torch front-end


def face_normals_torch(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """Unit face normals ``(..., F, 3)`` of ``verts (..., V, 3)``, ``faces (F, 3)`` int64, in ``verts``' dtype
    and device, differentiable."""
    return _unit(_TORCH, _face_cross(_TORCH, verts, faces))


def vertex_normals_torch(verts: torch.Tensor, faces: torch.Tensor, weighting: str = "area") -> torch.Tensor:
    """Unit vertex normals ``(..., V, 3)`` of ``verts (..., V, 3)``, ``faces (F, 3)`` int64 (area-weighted by
    default, as :func:`vertex_normals`), in ``verts``' dtype and device, differentiable."""
    return _unit(_TORCH, _vertex_sum(_TORCH, verts, faces, weighting))


def angle_weighted_normals(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit face normals ``(T, F, 3)`` and unit vertex normals ``(T, V, 3)`` weighted by each corner's interior
    angle (libigl's ``PER_VERTEX_NORMALS_WEIGHTING_TYPE_ANGLE``: the pseudonormal of a closed mesh's vertex), of
    ``verts (T, V, 3)``, float64, all frames at once."""
    verts = np.asarray(verts, np.float64)
    faces = np.asarray(faces, np.int64)
    T, V = verts.shape[:2]
    tri = verts[:, faces]  # (T, F, 3 corners, 3)
    n = face_cross(verts, faces)
    fn = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    e_next = np.roll(tri, -1, axis=2) - tri
    e_prev = np.roll(tri, 1, axis=2) - tri
    cos = np.einsum("tfcd,tfcd->tfc", e_next, e_prev) / np.maximum(
        np.linalg.norm(e_next, axis=-1) * np.linalg.norm(e_prev, axis=-1), 1e-300)
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    flat = (np.arange(T)[:, None, None] * V + faces[None]).reshape(-1)  # (T F 3,) flat vertex of each corner
    weighted = (angle[..., None] * fn[:, :, None]).reshape(-1, 3)
    vn = np.stack([np.bincount(flat, weighted[:, k], T * V) for k in range(3)], 1).reshape(T, V, 3)
    vn /= np.maximum(np.linalg.norm(vn, axis=-1, keepdims=True), 1e-300)
    return fn, vn
