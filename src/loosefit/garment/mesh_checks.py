"""Topology and quality checks of triangle meshes: edges, boundary loops, manifoldness,
orientation, connected components, triangle shape. Used by the templates, the importer and tests."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components


def unique_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undirected edges of a triangle mesh.

    Args:
        faces: ``(F, 3)`` int triangles.

    Returns:
        ``edges (E, 2)`` int64 sorted vertex pairs, ``face_edge (F, 3)`` int64 id of the edge from
        corner ``c`` to corner ``c + 1`` of each face, ``count (E,)`` number of faces on each edge.
    """
    faces = np.asarray(faces, dtype=np.int64)
    half = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    lo, hi = half.min(1), half.max(1)
    base = int(hi.max()) + 1 if len(hi) else 1
    # 1D integer keys: much faster than np.unique(axis=0).
    keys, inverse, count = np.unique(lo * base + hi, return_inverse=True, return_counts=True)
    edges = np.stack([keys // base, keys % base], 1)
    return edges, inverse.reshape(-1, 3), count


def vertex_components(num_verts: int, faces: np.ndarray) -> np.ndarray:
    """``(V,)`` int component label of each vertex (vertices connected through faces); vertices on no
    face get their own label."""
    faces = np.asarray(faces, dtype=np.int64)
    rows = faces.reshape(-1)
    cols = np.roll(faces, -1, axis=1).reshape(-1)
    adj = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(num_verts, num_verts))
    return connected_components(adj, directed=False)[1]


def face_components(faces: np.ndarray) -> np.ndarray:
    """``(F,)`` int component label of each face (faces connected through shared vertices)."""
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return np.zeros(0, np.int64)
    labels = vertex_components(int(faces.max()) + 1, faces)
    return labels[faces[:, 0]]


class BoundaryError(ValueError):
    """A boundary that is not made of simple loops, at ``vertex`` (an id of the mesh checked: callers that
    renumbered a file's vertices name it by the file's number)."""

    def __init__(self, message: str, vertex: int):
        super().__init__(message)
        self.vertex = int(vertex)


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Ordered boundary loops of an edge-manifold mesh, each an int64 array of vertex ids following
    the faces' orientation. Raises :class:`BoundaryError` (a ``ValueError``) where boundary vertices are not
    simple (a vertex on two boundary loops, or a fan that touches the boundary twice)."""
    faces = np.asarray(faces, dtype=np.int64)
    half = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    key = half[:, 0] * (faces.max() + 1 if len(faces) else 1) + half[:, 1]
    rkey = half[:, 1] * (faces.max() + 1 if len(faces) else 1) + half[:, 0]
    border = half[~np.isin(key, rkey)]
    if len(border) == 0:
        return []
    nxt = {}
    for a, b in border:
        if a in nxt:
            raise BoundaryError(f"vertex {a} starts two boundary edges (non-manifold vertex)", a)
        nxt[a] = b
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            if v not in nxt:
                raise BoundaryError(f"boundary is not closed at vertex {v}", v)
            v = nxt[v]
        if v != start:
            raise BoundaryError(f"boundary loop through vertex {v} is not simple", v)
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def orientation(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Consistent face orientation over the sheets of a mesh: faces glued along edges that have exactly
    two faces (edges of three or more faces glue nothing here).

    Two glued faces agree when they run their common edge in opposite directions. Each sheet is walked
    breadth first from its first face; a face reached is flipped when it disagrees with the face it was
    reached from. A glued pair that still disagrees once every face is set makes its sheet
    non-orientable (a Moebius-like strip). Each sheet then keeps the orientation most of its faces have.

    Args:
        faces: ``(F, 3)`` int triangles.

    Returns:
        ``flip (F,)`` bool, the faces to reverse; ``conflicts (K, 2)`` int64 glued face pairs that disagree
        whatever the flips (none on an orientable mesh); ``sheet (F,)`` int64 sheet label of each face.
    """
    faces = np.asarray(faces, dtype=np.int64)
    nf = len(faces)
    if nf == 0:
        return np.zeros(0, bool), np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
    _, face_edge, count = unique_edges(faces)
    he = face_edge.reshape(-1)  # half edge h = 3 f + c runs from corner c to corner c + 1
    order = np.argsort(he, kind="stable")
    first = np.nonzero(np.r_[True, he[order][1:] != he[order][:-1]])[0]
    first = first[count[he[order[first]]] == 2]
    h1, h2 = order[first], order[first + 1]
    f1, f2 = h1 // 3, h2 // 3
    same = (faces[f1, h1 % 3] == faces[f2, h2 % 3]).astype(np.int8)  # both run a -> b: they disagree
    graph = sp.coo_matrix((np.ones(len(f1)), (f1, f2)), shape=(nf, nf))
    _, sheet = connected_components(graph, directed=False)
    # One breadth-first walk from a root joined to the first face of every sheet.
    roots = np.unique(sheet, return_index=True)[1]
    rows = np.r_[f1, f2, np.full(len(roots), nf)]
    cols = np.r_[f2, f1, roots]
    walk = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(nf + 1, nf + 1)).tocsr()
    visit, pred = breadth_first_order(walk, nf, directed=False, return_predecessors=True)
    disagree = dict(zip((np.minimum(f1, f2) * nf + np.maximum(f1, f2)).tolist(), same.tolist()))
    parity = [0] * (nf + 1)
    for f, p in zip(visit[1:].tolist(), pred[visit[1:]].tolist()):
        if p != nf:
            parity[f] = parity[p] ^ disagree[min(f, p) * nf + max(f, p)]
    flip = np.asarray(parity[:nf], bool)
    bad = (flip[f1] ^ flip[f2]) != same.astype(bool)
    majority = np.bincount(sheet, weights=flip) * 2 > np.bincount(sheet)
    flip ^= majority[sheet]
    return flip, np.stack([f1[bad], f2[bad]], 1), sheet.astype(np.int64)


def triangle_angles(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(F, 3)`` interior angles of each triangle at each corner, degrees (0 for degenerate ones)."""
    tri = np.asarray(verts, dtype=np.float64)[faces]
    out = np.zeros(tri.shape[:2])
    for c in range(3):
        u = tri[:, (c + 1) % 3] - tri[:, c]
        w = tri[:, (c + 2) % 3] - tri[:, c]
        cross = np.linalg.norm(np.cross(u, w), axis=1)
        out[:, c] = np.degrees(np.arctan2(cross, np.einsum("ij,ij->i", u, w)))
    return out


def face_areas(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(F,)`` triangle areas, square metres."""
    tri = np.asarray(verts, dtype=np.float64)[faces]
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


@dataclass
class MeshReport:
    """What :func:`mesh_report` found. Each list holds offending element ids (vertices, edges as
    vertex pairs, faces); empty lists mean the property holds."""

    num_verts: int
    num_faces: int
    num_components: int
    degenerate_faces: list = field(default_factory=list)
    duplicate_faces: list = field(default_factory=list)
    nonmanifold_edges: list = field(default_factory=list)
    nonmanifold_verts: list = field(default_factory=list)
    misoriented_edges: list = field(default_factory=list)
    unreferenced_verts: list = field(default_factory=list)
    num_boundary_loops: int = 0
    min_angle: float = 0.0
    mean_edge: float = 0.0

    @property
    def ok(self) -> bool:
        """One component, edge- and vertex-manifold, consistently oriented, no degenerate,
        duplicate or unused elements."""
        return self.num_components == 1 and not (
            self.degenerate_faces
            or self.duplicate_faces
            or self.nonmanifold_edges
            or self.nonmanifold_verts
            or self.misoriented_edges
            or self.unreferenced_verts
        )


def nonmanifold_vertices(num_verts: int, faces: np.ndarray) -> np.ndarray:
    """Vertices whose incident faces do not form one fan (a disk or a half disk): the faces around
    the vertex, linked through the edges they share at it, fall in more than one group."""
    faces = np.asarray(faces, dtype=np.int64)
    nf = len(faces)
    # Corner (f, c): the wedge at vertex faces[f, c], bounded by edges to the two other corners.
    corner_vertex = faces.reshape(-1)
    nxt = np.roll(faces, -1, axis=1).reshape(-1)
    prv = np.roll(faces, 1, axis=1).reshape(-1)
    # Two corners at the same vertex are linked when they share the edge to a third vertex.
    keys = np.concatenate([corner_vertex * num_verts + nxt, corner_vertex * num_verts + prv])
    ids = np.concatenate([np.arange(3 * nf), np.arange(3 * nf)])
    order = np.argsort(keys, kind="stable")
    ks, iss = keys[order], ids[order]
    same = ks[1:] == ks[:-1]
    adj = sp.coo_matrix(
        (np.ones(same.sum()), (iss[:-1][same], iss[1:][same])), shape=(3 * nf, 3 * nf)
    )
    _, wedge = connected_components(adj, directed=False)
    groups = np.unique(corner_vertex * (3 * nf) + wedge)
    fans = np.bincount(groups // (3 * nf), minlength=num_verts)
    return np.nonzero(fans > 1)[0]


def mesh_report(verts: np.ndarray, faces: np.ndarray, area_eps: float = 1e-12) -> MeshReport:
    """Check a triangle mesh.

    Args:
        verts: ``(V, 3)`` positions.
        faces: ``(F, 3)`` int triangles.
        area_eps: faces with less area (square metres) count as degenerate.
    """
    verts = np.asarray(verts, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    nv = len(verts)
    used = np.zeros(nv, bool)
    used[faces.reshape(-1)] = True
    areas = face_areas(verts, faces)
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    degenerate = np.nonzero(repeated | (areas <= area_eps))[0]
    sf = np.sort(faces, 1)
    _, first = np.unique((sf[:, 0] * nv + sf[:, 1]) * nv + sf[:, 2], return_index=True)
    dup_mask = np.ones(len(faces), bool)
    dup_mask[first] = False
    edges, _, count = unique_edges(faces)
    half = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    directed, dcount = np.unique(half[:, 0] * nv + half[:, 1], return_counts=True)
    misoriented = np.stack([directed // nv, directed % nv], 1)[dcount > 1]
    labels = face_components(faces)
    try:
        loops = len(boundary_loops(faces)) if len(faces) else 0
    except ValueError:
        loops = -1
    angles = triangle_angles(verts, faces)
    lengths = np.linalg.norm(verts[edges[:, 0]] - verts[edges[:, 1]], axis=1)
    return MeshReport(
        num_verts=nv,
        num_faces=len(faces),
        num_components=len(np.unique(labels)),
        degenerate_faces=degenerate.tolist(),
        duplicate_faces=np.nonzero(dup_mask)[0].tolist(),
        nonmanifold_edges=edges[count > 2].tolist(),
        nonmanifold_verts=nonmanifold_vertices(nv, faces).tolist(),
        misoriented_edges=misoriented.tolist(),
        unreferenced_verts=np.nonzero(~used)[0].tolist(),
        num_boundary_loops=loops,
        min_angle=float(angles.min()) if len(faces) else 0.0,
        mean_edge=float(lengths.mean()) if len(lengths) else 0.0,
    )
