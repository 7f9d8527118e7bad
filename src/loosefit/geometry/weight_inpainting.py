"""Skinning weights for a loose garment by inpainting (after Abdrashitov et al. 2023, "Robust skin weights
transfer via weight inpainting", SIGGRAPH Asia Technical Communications; their normal test left out).

Copying each garment vertex's weights from its closest body vertex (body-LBS, FitGar's indicator ``I``)
is right where the garment lies on the body and wrong where it hangs free: a long skirt's hem takes the
weights of whichever shin is closest, and splits between the legs when they part. Here the weights are
copied only where the garment is within ``max_distance`` of the body, and filled in elsewhere by the
harmonic interpolation of the copied ones over the garment mesh (the Laplace equation ``L W = 0`` on the free
vertices, the copied weights as boundary values): a free vertex blends the bones of the body parts it hangs
from, by how far along the cloth it is from each.

The Laplacian is the cotangent one (the geometry's, so the blend does not lean along the triangulation's
diagonals as the graph Laplacian's does), with negative edge weights (angles above 90 degrees) set to 0: the
solution then obeys the discrete maximum principle, every weight stays in ``[0, 1]`` and every row sums to 1
(constants are harmonic and the copied rows sum to 1). A part of the garment that no copied vertex reaches
through positive weights keeps the closest body vertex's weights.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu
from scipy.spatial import cKDTree

from loosefit.errors import InputError
from loosefit.geometry.laplacian import check_mesh, cotangent_laplacian


def inpainted_skinning_weights(garment_verts: np.ndarray, faces: np.ndarray, body_verts: np.ndarray,
                               body_weights: np.ndarray, max_distance: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """Skinning weights of a garment in the body's rest pose (see the module docstring).

    Args:
        garment_verts: ``(V, 3)`` rest garment, metres. faces: ``(F, 3)`` its triangles.
        body_verts: ``(B, 3)`` rest body vertices, metres. body_weights: ``(B, J)`` their skinning weights.
        max_distance: metres: a garment vertex this close to a body vertex copies that vertex's weights.

    Returns:
        ``(V, J)`` float64 weights (rows sum to 1) and the ``(V,)`` bool mask of the copied rows.
    """
    g, faces = check_mesh(garment_verts, faces)
    if g.ndim != 2:
        raise InputError(f"inpainted_skinning_weights takes one garment (V, 3), got {g.shape}")
    b = np.asarray(body_verts, np.float64)
    w = np.asarray(body_weights, np.float64)
    if b.ndim != 2 or b.shape[1] != 3 or w.ndim != 2 or len(w) != len(b) or not np.isfinite(b).all():
        raise InputError(f"body vertices (B, 3) and weights (B, J) must match, got {b.shape} and {w.shape}")
    if not (np.isfinite(max_distance) and max_distance >= 0):
        raise InputError(f"max_distance must be a non-negative number of metres, got {max_distance!r}")
    distance, nearest = cKDTree(b).query(g)
    out = w[nearest].copy()
    known = distance <= max_distance
    L = laplacian_for_inpainting(g, faces)
    # the free vertices of a part that no copied vertex reaches keep their closest body vertex's weights
    _, part = connected_components(L, directed=False)
    anchored = np.isin(part, np.unique(part[known]))
    free = np.flatnonzero(~known & anchored)
    if len(free):
        fixed = np.flatnonzero(known)
        # L_ff W_f = -L_fk W_k; -L_ff is a nonsingular M-matrix: each free vertex reaches a fixed one
        rhs = -(L[free][:, fixed] @ out[fixed])
        out[free] = splu(sp.csc_matrix(L[free][:, free])).solve(np.ascontiguousarray(rhs))
    return out, known


def laplacian_for_inpainting(verts: np.ndarray, faces: np.ndarray) -> sp.csr_matrix:
    """The cotangent Laplacian ``(V, V)`` of one mesh with its negative (and non-finite) edge weights set to 0 and
    the diagonal made again so that rows sum to 0: an M-matrix up to sign, for the maximum principle."""
    C = sp.coo_matrix(cotangent_laplacian(verts, faces))
    off = C.row != C.col
    keep = off & np.isfinite(C.data) & (C.data > 0)
    W = sp.csr_matrix((C.data[keep], (C.row[keep], C.col[keep])), shape=C.shape)
    W = (W + W.T) * 0.5  # symmetric by construction; this removes rounding
    return (W - sp.diags(np.asarray(W.sum(1)).ravel())).tocsr()
