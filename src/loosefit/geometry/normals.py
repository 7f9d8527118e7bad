"""Face areas, face normals and vertex normals, batched over frames (numpy).

All functions accept ``verts (V, 3)`` or ``(..., V, 3)`` (e.g. ``(T, V, 3)``) with ``faces (F, 3)``
and keep the leading dimensions. Normals follow the right-hand rule on the face's vertex order.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from loosefit.errors import InputError
from loosefit.geometry.laplacian import check_mesh


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Cross products of ``(..., 3)`` arrays; several times faster than ``np.cross`` on large batches."""
    u0, u1, u2 = u[..., 0], u[..., 1], u[..., 2]
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0], -1)


def face_cross(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unchecked: ``(..., F, 3)`` cross products ``(b - a) x (c - a)`` per face: direction = normal, length = 2 x area."""
    a, b, c = (verts[..., faces[:, k], :] for k in range(3))
    return cross(b - a, c - a)


def _normalise(v: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > eps)


def face_areas(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Triangle areas ``(..., F)`` in m^2."""
    verts, faces = check_mesh(verts, faces)
    return 0.5 * np.linalg.norm(face_cross(np.asarray(verts, np.float64), faces), axis=-1)


def face_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit face normals ``(..., F, 3)`` float32; zero vectors for degenerate (zero-area) triangles."""
    verts, faces = check_mesh(verts, faces)
    return _normalise(face_cross(np.asarray(verts, np.float64), faces)).astype(np.float32)


def vertex_normals(verts: np.ndarray, faces: np.ndarray, weighting: str = "area") -> np.ndarray:
    """Unit vertex normals ``(..., V, 3)`` float32: normalised weighted sum of the incident face normals.

    ``weighting``: ``"area"`` (face normal times face area, the usual choice for cloth) or
    ``"uniform"`` (unit face normals). Vertices in no triangle get a zero normal.
    """
    verts, faces = check_mesh(verts, faces)
    if weighting not in ("area", "uniform"):
        raise InputError(f"vertex normal weighting must be 'area' or 'uniform', got {weighting!r}")
    cross = face_cross(np.asarray(verts, np.float64), faces)  # (..., F, 3), length = 2 area
    if weighting == "uniform":
        cross = _normalise(cross)
    V, F = verts.shape[-2], len(faces)
    # Sparse vertex-face incidence sums each face's vector onto its three corners for all frames at once.
    incidence = sp.csr_matrix((np.ones(3 * F), (faces.T.ravel(), np.tile(np.arange(F), 3))), shape=(V, F))
    lead = cross.shape[:-2]
    flat = np.moveaxis(cross.reshape((-1, F, 3)), 1, 0).reshape(F, -1)  # (F, batch*3)
    summed = (incidence @ flat).reshape(V, -1, 3)
    return _normalise(np.moveaxis(summed, 0, 1)).reshape(lead + (V, 3)).astype(np.float32)
