"""Isotropic remeshing to a target edge length (split long edges, collapse short ones, flip edges
towards valence 6, tangential relaxation), with vertices kept on a reference surface and boundary
vertices on its boundary curves.

Every operation is applied to a batch of independent edges at once (numpy), so a 20k-vertex mesh
remeshes in seconds. The input must be an edge-manifold, consistently oriented triangle mesh; the
output is too, with the same boundary loops and topology.
"""

from __future__ import annotations

import igl
import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from loosefit.garment.mesh_checks import boundary_loops, unique_edges
from loosefit.geometry.normals import face_normals, vertex_normals


class ReferenceSurface:
    """Closest-point projection onto a triangle mesh and onto its boundary curves.

    Args:
        verts: ``(V, 3)`` positions, metres.
        faces: ``(F, 3)`` int triangles.
        spacing: boundary curves are sampled this densely (metres) for their projection.
    """

    def __init__(self, verts: np.ndarray, faces: np.ndarray, spacing: float):
        self.verts = np.ascontiguousarray(verts, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self._tree = igl.AABB()
        self._tree.init(self.verts, self.faces)
        samples = []
        for loop in boundary_loops(self.faces):
            a, b = self.verts[loop], self.verts[np.roll(loop, -1)]
            n = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / spacing).astype(int))
            t = np.concatenate([np.arange(k) / k for k in n])
            samples.append(np.repeat(a, n, 0) + t[:, None] * np.repeat(b - a, n, 0))
        self._border = np.concatenate(samples) if samples else np.zeros((0, 3))
        self._border_tree = cKDTree(self._border) if samples else None

    def project(self, points: np.ndarray) -> np.ndarray:
        """``(N, 3)`` closest points on the surface."""
        if len(points) == 0:
            return points
        return self._tree.squared_distance(self.verts, self.faces, np.ascontiguousarray(points))[2]

    def project_border(self, points: np.ndarray) -> np.ndarray:
        """``(N, 3)`` closest points on the boundary curves (within the sampling spacing)."""
        if len(points) == 0 or self._border_tree is None:
            return points
        return self._border[self._border_tree.query(points)[1]]


def _adjacency(num_verts: int, edges: np.ndarray) -> sp.csr_matrix:
    data = np.ones(2 * len(edges))
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    return sp.csr_matrix((data, (rows, cols)), shape=(num_verts, num_verts))


def _boundary_verts(num_verts: int, edges: np.ndarray, count: np.ndarray) -> np.ndarray:
    mask = np.zeros(num_verts, bool)
    mask[edges[count == 1].reshape(-1)] = True
    return mask


def _face_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit face normals ``(..., F, 3)`` float64 that keep the direction of nearly degenerate triangles too (the
    flip checks compare directions)."""
    return face_normals(verts, faces, np.float64, eps=1e-30)


def split_long_edges(verts: np.ndarray, faces: np.ndarray, max_length: float, passes: int = 12):
    """Split every edge longer than ``max_length`` at its midpoint (each pass splits, in every face,
    at most its longest long edge). Returns new ``(verts, faces)``."""
    for _ in range(passes):
        edges, face_edge, count = unique_edges(faces)
        length = np.linalg.norm(verts[edges[:, 0]] - verts[edges[:, 1]], axis=1)
        long = length > max_length
        if not long.any():
            break
        face_len = np.where(long[face_edge], length[face_edge], -1.0)
        best_corner = face_len.argmax(1)
        has = face_len.max(1) > 0
        best = np.where(has, face_edge[np.arange(len(faces)), best_corner], -1)
        votes = np.bincount(best[has], minlength=len(edges))
        chosen = long & (votes == count)  # longest long edge in all of its faces
        new_id = np.full(len(edges), -1)
        new_id[chosen] = len(verts) + np.arange(chosen.sum())
        verts = np.concatenate([verts, 0.5 * (verts[edges[chosen, 0]] + verts[edges[chosen, 1]])])
        f_idx = np.nonzero(has & chosen[np.maximum(best, 0)])[0]
        c = best_corner[f_idx]
        u = faces[f_idx, c]
        v = faces[f_idx, (c + 1) % 3]
        w = faces[f_idx, (c + 2) % 3]
        m = new_id[best[f_idx]]
        faces = faces.copy()
        faces[f_idx] = np.stack([u, m, w], 1)
        faces = np.concatenate([faces, np.stack([m, v, w], 1)])
    return verts, faces


def collapse_short_edges(verts: np.ndarray, faces: np.ndarray, min_length: float, max_length: float):
    """Collapse edges shorter than ``min_length`` where that keeps the mesh manifold, creates no edge
    longer than ``max_length``, flips no face and keeps boundary vertices on the boundary.
    Returns new ``(verts, faces)``."""
    nv = len(verts)
    edges, face_edge, count = unique_edges(faces)
    length = np.linalg.norm(verts[edges[:, 0]] - verts[edges[:, 1]], axis=1)
    on_border = _boundary_verts(nv, edges, count)
    cand = np.nonzero(length < min_length)[0]
    a, b = edges[cand, 0].copy(), edges[cand, 1].copy()
    # Keep the boundary vertex where one end is on the boundary; never join two boundary
    # vertices through the interior.
    swap = on_border[b] & ~on_border[a]
    a[swap], b[swap] = b[swap], a[swap]
    ok = ~(on_border[a] & on_border[b] & (count[cand] != 1))
    adj = _adjacency(nv, edges)
    valence = np.diff(adj.indptr)
    common = np.asarray(adj[a].multiply(adj[b]).sum(1)).reshape(-1)
    ok &= common == count[cand]  # link condition
    target = np.where((on_border[a] & ~on_border[b])[:, None], verts[a], 0.5 * (verts[a] + verts[b]))
    # Longest edge from the merged vertex and flipped faces around it.
    inc = sp.csr_matrix(
        (np.ones(faces.size), (faces.reshape(-1), np.repeat(np.arange(len(faces)), 3))), shape=(nv, len(faces))
    )
    normals = _face_normals(verts, faces)
    for end in (a, b):
        rows = adj[end].tocoo()
        far = np.linalg.norm(target[rows.row] - verts[rows.col], axis=1)
        worst = np.zeros(len(cand))
        np.maximum.at(worst, rows.row, far)
        ok &= worst < max_length
        frows = inc[end].tocoo()
        f = faces[frows.col]
        moved = verts[f]
        hit = (f == a[frows.row, None]) | (f == b[frows.row, None])
        keep = hit.sum(1) == 1  # faces that survive the collapse
        moved[hit] = np.repeat(target[frows.row], 3, 0).reshape(-1, 3, 3)[hit]
        n_new = _face_normals(moved, np.array([[0, 1, 2]]))[:, 0]  # each moved triangle on its own
        bad = keep & (np.einsum("ij,ij->i", n_new, normals[frows.col]) < 0.3)
        ok &= np.bincount(frows.row[bad], minlength=len(cand)) == 0
    # The two vertices opposite an interior edge lose a neighbour: keep them at valence >= 4.
    opp = _opposite_vertices(faces, face_edge, cand)
    for o in opp:
        valid = o >= 0
        low = np.zeros(len(cand), bool)
        low[valid] = valence[o[valid]] - 1 < np.where(on_border[o[valid]], 2, 4)
        ok &= ~low
    order = np.argsort(length[cand])
    locked = np.zeros(nv, bool)
    chosen = []
    indptr, indices = adj.indptr, adj.indices
    for i in order:
        if not ok[i] or locked[a[i]] or locked[b[i]]:
            continue
        chosen.append(i)
        locked[indices[indptr[a[i]] : indptr[a[i] + 1]]] = True
        locked[indices[indptr[b[i]] : indptr[b[i] + 1]]] = True
        locked[a[i]] = locked[b[i]] = True
    if not chosen:
        return verts, faces
    chosen = np.array(chosen)
    verts = verts.copy()
    verts[a[chosen]] = target[chosen]
    remap = np.arange(nv)
    remap[b[chosen]] = a[chosen]
    faces = remap[faces]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]
    return compact(verts, faces)


def _opposite_vertices(faces: np.ndarray, face_edge: np.ndarray, edge_ids: np.ndarray) -> list[np.ndarray]:
    """For each edge in ``edge_ids``, the vertex opposite it in its first and second face (-1 if none)."""
    flat = face_edge.reshape(-1)
    out = [np.full(len(edge_ids), -1), np.full(len(edge_ids), -1)]
    pos = np.full(int(flat.max()) + 1 if len(flat) else 0, -1)
    pos[edge_ids] = np.arange(len(edge_ids))
    slot = pos[flat]
    sel = np.nonzero(slot >= 0)[0]
    opposite = faces.reshape(-1)[(sel // 3) * 3 + (sel % 3 + 2) % 3]
    first = np.ones(len(sel), bool)
    order = np.argsort(slot[sel], kind="stable")
    s_sorted = slot[sel][order]
    first[order[1:]] = s_sorted[1:] != s_sorted[:-1]
    out[0][slot[sel][first]] = opposite[first]
    out[1][slot[sel][~first]] = opposite[~first]
    return out


def _interior_edge_quads(faces: np.ndarray, face_edge: np.ndarray, count: np.ndarray):
    """For every interior edge: its two faces ``f1, f2`` and vertices ``a, b`` (the edge, as
    ``a -> b`` in ``f1``), ``c`` (opposite in ``f1``) and ``d`` (opposite in ``f2``)."""
    he_edge = face_edge.reshape(-1)
    order = np.argsort(he_edge, kind="stable")
    e_sorted = he_edge[order]
    pair_start = np.nonzero(np.r_[True, e_sorted[1:] != e_sorted[:-1]])[0]
    interior = count[e_sorted[pair_start]] == 2
    h1 = order[pair_start[interior]]
    h2 = order[pair_start[interior] + 1]
    f1, c1, f2, c2 = h1 // 3, h1 % 3, h2 // 3, h2 % 3
    return f1, f2, faces[f1, c1], faces[f1, (c1 + 1) % 3], faces[f1, (c1 + 2) % 3], faces[f2, (c2 + 2) % 3]


def _corner_angle(verts: np.ndarray, at: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    u, w = verts[p] - verts[at], verts[q] - verts[at]
    return np.arctan2(np.linalg.norm(np.cross(u, w), axis=1), np.einsum("ij,ij->i", u, w))


def flip_edges(verts: np.ndarray, faces: np.ndarray, criterion: str = "valence") -> np.ndarray:
    """Flip interior edges of a triangle mesh. Returns new faces.

    ``criterion="valence"`` flips where that brings the four vertices' valences closer to 6
    (4 on the boundary); ``"delaunay"`` flips where the two angles opposite the edge sum to more
    than pi (which raises the smallest angle). Flips that would fold the two faces are skipped.
    """
    nv = len(verts)
    edges, face_edge, count = unique_edges(faces)
    f1, f2, a, b, c, d = _interior_edge_quads(faces, face_edge, count)
    valence = np.bincount(edges.reshape(-1), minlength=nv)
    if criterion == "valence":
        ideal = np.where(_boundary_verts(nv, edges, count), 4, 6)
        dev = lambda v, k: (valence[v] + k - ideal[v]) ** 2  # noqa: E731
        gain = (dev(a, 0) + dev(b, 0) + dev(c, 0) + dev(d, 0) - dev(a, -1) - dev(b, -1) - dev(c, 1) - dev(d, 1)).astype(float)
    else:
        gain = _corner_angle(verts, c, a, b) + _corner_angle(verts, d, b, a) - np.pi - 1e-3
    adj = _adjacency(nv, edges)
    exists = np.asarray(adj[c, d]).reshape(-1) > 0
    new1 = np.stack([a, d, c], 1)
    new2 = np.stack([d, b, c], 1)
    n_old = _face_normals(verts, faces)
    ref = n_old[f1] + n_old[f2]
    ref /= np.maximum(np.linalg.norm(ref, axis=1, keepdims=True), 1e-30)
    good = (np.einsum("ij,ij->i", _face_normals(verts, new1), ref) > 0.5) & (
        np.einsum("ij,ij->i", _face_normals(verts, new2), ref) > 0.5
    )
    ok = (gain > 0) & ~exists & good & (valence[a] > 3) & (valence[b] > 3)
    # At most one flip per face: each face keeps its best candidate.
    score = np.where(ok, gain, 0.0)
    best = np.full(len(faces), -1.0)
    np.maximum.at(best, f1, score)
    np.maximum.at(best, f2, score)
    idx = np.nonzero(ok & (best[f1] == score) & (best[f2] == score))[0]
    face_used = np.zeros(len(faces), bool)
    new_keys = set()
    faces = faces.copy()
    for i in idx:  # resolve ties on shared faces and duplicate new edges
        key = (min(c[i], d[i]), max(c[i], d[i]))
        if face_used[f1[i]] or face_used[f2[i]] or key in new_keys:
            continue
        face_used[f1[i]] = face_used[f2[i]] = True
        new_keys.add(key)
        faces[f1[i]] = new1[i]
        faces[f2[i]] = new2[i]
    return faces


def relax(verts: np.ndarray, faces: np.ndarray, surface: ReferenceSurface | None, steps: int = 2, rate: float = 0.6):
    """Tangential smoothing: move vertices towards their neighbours' centroid within the tangent
    plane (boundary vertices along their boundary), then back onto ``surface``."""
    nv = len(verts)
    edges, _, count = unique_edges(faces)
    border_edges = edges[count == 1]
    on_border = _boundary_verts(nv, edges, count)
    lap = _adjacency(nv, edges)
    blap = _adjacency(nv, border_edges)
    deg = np.maximum(np.asarray(lap.sum(1)).reshape(-1), 1)
    bdeg = np.maximum(np.asarray(blap.sum(1)).reshape(-1), 1)
    for _ in range(steps):
        n = vertex_normals(verts, faces)
        delta = lap @ verts / deg[:, None] - verts
        delta -= np.einsum("ij,ij->i", delta, n)[:, None] * n
        bdelta = blap @ verts / bdeg[:, None] - verts
        delta[on_border] = bdelta[on_border]
        verts = verts + rate * delta
        if surface is not None:
            inner = ~on_border
            verts[inner] = surface.project(verts[inner])
            verts[on_border] = surface.project_border(verts[on_border])
    return verts


def compact(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop vertices no face uses; returns ``(verts, faces)`` renumbered."""
    used = np.zeros(len(verts), bool)
    used[faces.reshape(-1)] = True
    remap = np.cumsum(used) - 1
    return verts[used], remap[faces]


def remove_ears(verts: np.ndarray, faces: np.ndarray, max_angle: float = 150.0) -> np.ndarray:
    """Drop boundary triangles that are a single flat corner of the boundary (a boundary vertex on
    only this face, its angle there above ``max_angle`` degrees). Returns new faces."""
    nv = len(verts)
    faces_per_vertex = np.bincount(faces.reshape(-1), minlength=nv)
    edges, _, count = unique_edges(faces)
    on_border = _boundary_verts(nv, edges, count)
    keep = np.ones(len(faces), bool)
    for c in range(3):
        at, p, q = faces[:, c], faces[:, (c + 1) % 3], faces[:, (c + 2) % 3]
        ear = on_border[at] & (faces_per_vertex[at] == 1)
        keep &= ~(ear & (np.degrees(_corner_angle(verts, at, p, q)) > max_angle))
    return faces[keep]


def clean_up(verts: np.ndarray, faces: np.ndarray, edge_length: float) -> tuple[np.ndarray, np.ndarray]:
    """Remove the few badly shaped triangles a deformation left: flat boundary corners, very short
    edges (below half ``edge_length``), then Delaunay flips. Returns ``(verts, faces)``."""
    faces = remove_ears(verts, faces)
    verts, faces = compact(verts, faces)
    verts, faces = collapse_short_edges(verts, faces, 0.5 * edge_length, 1.6 * edge_length)
    for _ in range(3):
        faces = flip_edges(verts, faces, "delaunay")
    return verts, faces


def remesh(
    verts: np.ndarray, faces: np.ndarray, edge_length: float, iterations: int = 6, surface: ReferenceSurface | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Isotropic remeshing.

    Args:
        verts: ``(V, 3)`` positions, metres.
        faces: ``(F, 3)`` int64 triangles, edge-manifold and consistently oriented.
        edge_length: target edge length, metres.
        iterations: rounds of split / collapse / flip / relax.
        surface: where vertices are kept; by default the input mesh itself.

    Returns:
        ``verts (V', 3)`` float64 and ``faces (F', 3)`` int64 with edges near ``edge_length``.
    """
    verts = np.asarray(verts, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if surface is None:
        surface = ReferenceSurface(verts, faces, spacing=edge_length / 20)
    lo, hi = 0.8 * edge_length, 4.0 / 3.0 * edge_length
    for _ in range(iterations):
        verts, faces = split_long_edges(verts, faces, hi)
        verts, faces = collapse_short_edges(verts, faces, lo, hi)
        faces = flip_edges(verts, faces)
        verts = relax(verts, faces, surface)
    for _ in range(3):
        faces = flip_edges(verts, faces, "delaunay")
    return verts, faces
