"""Mesh connectivity and Laplace operators: edges, adjacency, boundary, cotangent Laplacian, mass matrix.

Sign convention (libigl's): the cotangent Laplacian ``L`` is negative semi-definite, off-diagonal
``L_ij = (cot a_ij + cot b_ij) / 2`` (the half-cotangent weights of the two angles opposite edge
``ij``) and ``L_ii = -sum_j L_ij``, so ``L`` applied to a constant is zero. ``L`` is dimensionless
(cotangents are scale invariant); ``M^-1 L x`` approximates the Laplace-Beltrami operator in 1/m^2.
"""

from __future__ import annotations

import igl
import numpy as np
import scipy.sparse as sp

from loosefit.errors import InputError


def check_mesh(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate a triangle mesh; return ``(verts (..., V, 3) float, faces (F, 3) int64)``.

    Raises :class:`InputError` on wrong shapes, out-of-range indices or non-finite positions.
    """
    verts = np.asarray(verts)
    faces = np.asarray(faces)
    if verts.ndim < 2 or verts.shape[-1] != 3:
        raise InputError(f"vertices must have shape (..., V, 3), got {verts.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise InputError(f"faces must have shape (F, 3) with F > 0, got {faces.shape}")
    if not np.issubdtype(faces.dtype, np.integer):
        raise InputError(f"faces must be integer indices, got dtype {faces.dtype}")
    if faces.min() < 0 or faces.max() >= verts.shape[-2]:
        raise InputError(f"faces index vertices outside [0, {verts.shape[-2]})")
    if not np.isfinite(verts).all():
        raise InputError("vertices contain NaN or infinite values")
    return verts, faces.astype(np.int64, copy=False)


def edges(faces: np.ndarray) -> np.ndarray:
    """Unique undirected edges ``(E, 2)`` int64 of a triangle mesh, each as ``(i, j)`` with ``i < j``, sorted."""
    faces = np.asarray(faces, dtype=np.int64)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.sort(e, axis=1)
    return np.unique(e, axis=0)


def adjacency(faces: np.ndarray, num_verts: int) -> sp.csr_matrix:
    """Symmetric 0/1 vertex adjacency ``(V, V)`` (float64) of the mesh edges."""
    e = edges(faces)
    ones = np.ones(len(e))
    A = sp.coo_matrix((np.r_[ones, ones], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(num_verts, num_verts))
    return A.tocsr()


def boundary_edges(faces: np.ndarray) -> np.ndarray:
    """Edges ``(B, 2)`` used by exactly one triangle (the mesh's open borders: hems, sleeves, necklines)."""
    faces = np.asarray(faces, dtype=np.int64)
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(e, axis=0, return_counts=True)
    return uniq[counts == 1]


def uniform_laplacian(faces: np.ndarray, num_verts: int) -> sp.csr_matrix:
    """Graph Laplacian ``A - D`` ``(V, V)``: each row sums to zero, ``(L x)_i = sum_j (x_j - x_i)``."""
    A = adjacency(faces, num_verts)
    return (A - sp.diags(np.asarray(A.sum(1)).ravel())).tocsr()


def cotangent_laplacian(verts: np.ndarray, faces: np.ndarray) -> sp.csr_matrix:
    """Cotangent Laplacian ``(V, V)`` float64 of one mesh ``verts (V, 3)`` (libigl ``cotmatrix``).

    Half-cotangent weights, negative semi-definite, rows summing to zero; see the module docstring.
    """
    verts, faces = check_mesh(verts, faces)
    if verts.ndim != 2:
        raise InputError(f"cotangent_laplacian takes one mesh (V, 3), got {verts.shape}")
    return igl.cotmatrix(np.ascontiguousarray(verts, dtype=np.float64), np.ascontiguousarray(faces)).tocsr()


def mass_matrix(verts: np.ndarray, faces: np.ndarray, kind: str = "voronoi") -> sp.csr_matrix:
    """Diagonal lumped mass matrix ``(V, V)`` in m^2 (libigl ``massmatrix``); its trace is the surface area.

    ``kind``: ``"voronoi"`` (mixed Voronoi areas, libigl's default for triangles) or ``"barycentric"``
    (a third of each incident triangle's area).
    """
    verts, faces = check_mesh(verts, faces)
    types = {"voronoi": igl.MASSMATRIX_TYPE_VORONOI, "barycentric": igl.MASSMATRIX_TYPE_BARYCENTRIC}
    if kind not in types:
        raise InputError(f"mass matrix kind must be one of {sorted(types)}, got {kind!r}")
    return igl.massmatrix(np.ascontiguousarray(verts, dtype=np.float64), np.ascontiguousarray(faces), types[kind]).tocsr()


def half_cotangents(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Half-cotangent of every triangle corner, batched: ``verts (..., V, 3)`` -> ``(..., F, 3)`` float64.

    Entry ``[..., f, k]`` is ``cot(angle at corner k of face f) / 2``: the weight this face gives to
    the edge opposite corner k. Degenerate (zero-area) triangles give 0 instead of infinity.
    """
    verts, faces = check_mesh(verts, faces)
    v = np.asarray(verts, dtype=np.float64)
    p = [v[..., faces[:, k], :] for k in range(3)]
    out = []
    for k in range(3):
        a = p[(k + 1) % 3] - p[k]
        b = p[(k + 2) % 3] - p[k]
        dot = (a * b).sum(-1)
        # |a x b| from Lagrange's identity: cheaper than np.cross on (T, F, 3) batches.
        cross = np.sqrt(np.clip((a * a).sum(-1) * (b * b).sum(-1) - dot * dot, 0.0, None))
        out.append(np.divide(dot, 2 * cross, out=np.zeros_like(dot), where=cross > 1e-300))
    return np.stack(out, -1)


def cotangent_laplacian_diagonal(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``diag(L)`` of the cotangent Laplacian for many frames at once: ``(..., V, 3)`` -> ``(..., V)`` float64.

    ``L_ii = -sum`` over the triangles around ``i`` of the half-cotangents of their two corners
    that are not at ``i`` (equal to ``cotangent_laplacian(verts, faces).diagonal()`` per frame).
    """
    verts, faces = check_mesh(verts, faces)
    hc = half_cotangents(verts, faces)  # (..., F, 3)
    # Corner k's vertex receives the half-cotangents of the other two corners.
    contrib = hc.sum(-1, keepdims=True) - hc  # (..., F, 3)
    V = verts.shape[-2]
    scatter = sp.csr_matrix((np.ones(faces.size), (faces.ravel(), np.arange(faces.size))), shape=(V, faces.size))
    lead = contrib.shape[:-2]
    flat = contrib.reshape(-1, faces.size).T  # (3F, batch)
    return -(scatter @ flat).T.reshape(lead + (V,))


def smoothest_modes(verts: np.ndarray, faces: np.ndarray, count: int) -> np.ndarray:
    """The ``count`` smoothest vibration modes of the surface ``(V, count)`` float64: the eigenvectors of the
    cotangent Laplacian with the lowest eigenvalues, ``-L phi = lambda M phi`` (:func:`cotangent_laplacian`,
    :func:`mass_matrix`), orthonormal in the mass inner product (``Phi^T M Phi = I``), lowest frequency first; the
    first is the constant on a connected mesh. A field ``f (V, C)`` keeps its smooth part as ``Phi Phi^T M f``. Modes
    of equal frequency (a symmetric garment's pairs) are one orthonormal basis of their span, not a unique one.

    Raises:
        InputError: ``count`` outside ``1 .. V - 1``.
    """
    from scipy.sparse.linalg import eigsh

    verts, faces = check_mesh(verts, faces)
    if not 1 <= count < len(verts):
        raise InputError(f"the mesh of {len(verts)} vertices has no {count} smoothest modes (1 to {len(verts) - 1})")
    L, M = -cotangent_laplacian(verts, faces), mass_matrix(verts, faces)
    # shift-invert just below zero: the lowest eigenvalues come first and the shifted matrix is not singular; a
    # fixed start vector and each mode's largest entry made positive give the same modes on every call
    values, modes = eigsh(L.tocsc(), k=count, M=M.tocsc(), sigma=-1e-6, which="LM", v0=np.ones(len(verts)))
    modes = modes[:, np.argsort(values)]
    return modes * np.sign(modes[np.abs(modes).argmax(0), np.arange(count)])
