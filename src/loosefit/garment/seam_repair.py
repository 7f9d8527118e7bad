"""Repairs of garment seams as pattern tools and datasets write them: welding duplicated seam
vertices, dropping sliver triangles, and splitting non-manifold edges and pinched vertices into
manifold fans.

Splitting: the faces around each vertex are linked through the edges they are glued along. An edge
with two faces glues them; an edge with more (three or more panels meeting at a seam) glues them in
pairs, greedily the pair that continues the surface most smoothly first (the opening angle between
the two faces, seen along the edge, nearest 180 degrees); faces left over are not glued there. Each
group of linked faces around a vertex then gets its own copy of the vertex, so every edge has at
most two faces and every vertex one fan. A panel attached only along a split seam becomes a
separate piece (the importer drops it when it is small, and refuses the mesh when it is not).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from loosefit.garment.mesh_checks import unique_edges


def weld(verts: np.ndarray, faces: np.ndarray, tol: float, return_kept: bool = False):
    """Merge vertices closer than ``tol`` (transitively) into their first one.

    Only pairs that are one point of the cloth written twice are merged: two ends of an edge (a collapsed edge),
    vertices with a common neighbour, or with neighbours that are themselves within ``tol`` (a seam written as
    two panels, a triangle soup), or a vertex no face uses. Two vertices of the surface that merely touch (a
    fold resting on itself in a draped garment) have neither and stay apart, and so do the tips of two triangles
    folded flat onto each other about their common edge (merged, they would be one face written twice).

    Args:
        verts: ``(V, 3)`` positions; faces: ``(F, 3)`` int64 triangles.
        tol: welding distance, in the units of ``verts``.

    Returns:
        ``(verts (V', 3), faces (F, 3), merged)``: unused merged vertices removed, file order kept
        otherwise; ``merged = V - V'``. With ``return_kept``, also ``kept (V',)``: the old id of each vertex
        kept (the first of those merged into it).
    """
    pairs = cKDTree(verts).query_pairs(tol, output_type="ndarray") if tol > 0 else np.zeros((0, 2), int)
    n = len(verts)
    if len(pairs):
        edges, face_edge, count = unique_edges(faces)
        # The tips of the two faces on each edge (face_edge[:, c] runs from corner c to c + 1).
        edge, tip = face_edge.ravel(), faces[:, [2, 0, 1]].ravel()
        order = np.argsort(edge, kind="stable")
        edge, tip = edge[order], tip[order]
        starts = np.nonzero((count[edge] == 2) & np.r_[True, edge[1:] != edge[:-1]])[0]
        folded = np.stack([tip[starts], tip[starts + 1]], 1)
        edges = edges[edges[:, 0] != edges[:, 1]]
        link = sp.coo_matrix((np.ones(2 * len(edges)), (edges.ravel(), edges[:, ::-1].ravel())), shape=(n, n)).tocsr()
        near = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        near = (near + near.T + sp.identity(n)).tocsr()
        # (A (I + W) A)[i, j] > 0: a common neighbour, or a neighbour of i within tol of one of j.
        reach = (link[pairs[:, 0]] @ near @ link).tocsr()
        linked = np.asarray(reach[np.arange(len(pairs)), pairs[:, 1]]).ravel() > 0
        linked |= np.asarray(link[pairs[:, 0], pairs[:, 1]]).ravel() > 0
        unused = np.ones(n, bool)
        unused[np.unique(faces)] = False
        key = lambda a: a.min(1) * n + a.max(1)  # noqa: E731
        linked &= ~np.isin(key(pairs), key(folded))
        pairs = pairs[linked | unused[pairs[:, 0]] | unused[pairs[:, 1]]]
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max() + 1, n)
    np.minimum.at(first, label, np.arange(n))
    keep = np.sort(first)
    rank = np.empty(label.max() + 1, np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    if return_kept:
        return verts[keep], rank[label][faces], int(n - len(keep)), keep
    return verts[keep], rank[label][faces], int(n - len(keep))


def slivers(verts: np.ndarray, faces: np.ndarray, ratio: float = 1e-3) -> np.ndarray:
    """``(F,)`` bool: triangles whose height is below ``ratio`` times their longest edge (zero-area
    slivers, collinear corners)."""
    tri = verts[faces]
    longest = np.max([np.linalg.norm(tri[:, (c + 1) % 3] - tri[:, c], axis=1) for c in range(3)], axis=0)
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return area2 / np.maximum(longest, 1e-300) <= ratio * longest


def _opening(verts: np.ndarray, a: int, b: int, c1: int, c2: int) -> float:
    """Angle (radians) between two triangles ``(a, b, c1)`` and ``(a, b, c2)`` seen along edge
    ``a-b``: pi when they continue each other flat, 0 when folded onto each other."""
    axis = verts[b] - verts[a]
    axis = axis / max(np.linalg.norm(axis), 1e-300)
    u = verts[c1] - verts[a]
    w = verts[c2] - verts[a]
    u = u - (u @ axis) * axis
    w = w - (w @ axis) * axis
    return float(np.arctan2(np.linalg.norm(np.cross(u, w)), u @ w))


def split_nonmanifold(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
    """Split non-manifold edges and pinched vertices into manifold fans (module docstring).

    Args:
        verts: ``(V, 3)`` positions; faces: ``(F, 3)`` int64 triangles without duplicates.

    Returns:
        ``(verts (V', 3), faces (F, 3), counts)`` with ``V' >= V`` (copies of split vertices
        appended), faces in the same order; ``counts`` has ``nonmanifold_edges`` (edges with more
        than two faces) and ``split_vertices`` (copies added).
    """
    faces = np.asarray(faces, np.int64)
    nf = len(faces)
    edges, face_edge, count = unique_edges(faces)
    he = face_edge.reshape(-1)  # half edge h = 3 f + c runs from corner c to corner c + 1
    order = np.argsort(he, kind="stable")
    starts = np.r_[0, np.cumsum(count)]
    glued = []  # pairs of half edges glued together
    for e in np.nonzero(count >= 2)[0]:
        hs = order[starts[e]:starts[e + 1]]
        if len(hs) == 2:
            glued.append((hs[0], hs[1]))
            continue
        a, b = edges[e]
        third = [int(faces[h // 3, (h % 3 + 2) % 3]) for h in hs]
        cand = sorted(
            ((abs(np.pi - _opening(verts, a, b, third[i], third[j])), i, j)
             for i in range(len(hs)) for j in range(i + 1, len(hs))),
        )
        used = set()
        for _, i, j in cand:
            if i not in used and j not in used:
                used |= {i, j}
                glued.append((hs[i], hs[j]))
    # Corner k = 3 f + c sits at faces[f, c]; half edge h touches corners h and next(h).
    rows, cols = [], []
    for h1, h2 in glued:
        f1, c1, f2, c2 = h1 // 3, h1 % 3, h2 // 3, h2 % 3
        n1, n2 = 3 * f1 + (c1 + 1) % 3, 3 * f2 + (c2 + 1) % 3
        if faces[f1, c1] == faces[f2, c2]:  # same direction (inconsistent orientation)
            rows += [h1, n1]
            cols += [h2, n2]
        else:
            rows += [h1, n1]
            cols += [n2, h2]
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * nf, 3 * nf))
    _, wedge = connected_components(graph, directed=False)
    corner_vertex = faces.reshape(-1)
    key = corner_vertex * (3 * nf) + wedge
    uniq, inverse = np.unique(key, return_inverse=True)
    owner = uniq // (3 * nf)
    # The first wedge of each vertex keeps the vertex id; the others get appended copies.
    first = np.r_[True, owner[1:] != owner[:-1]]
    new_id = np.where(first, owner, 0)
    extra = np.nonzero(~first)[0]
    new_id[extra] = len(verts) + np.arange(len(extra))
    verts = np.concatenate([verts, verts[owner[extra]]])
    faces = new_id[inverse].reshape(nf, 3)
    return verts, faces, {"nonmanifold_edges": int((count > 2).sum()), "split_vertices": int(len(extra))}
