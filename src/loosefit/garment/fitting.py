"""Placing garment surfaces at a distance from the body: inflating a patch of the body surface
into a smooth garment piece, and pushing a garment out of the body to a clearance."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from loosefit.garment.mesh_checks import unique_edges
from loosefit.geometry.normals import vertex_normals
from loosefit.geometry.signed_distance import BodySDF


def outward(sdf: BodySDF, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance ``(N,)`` of ``points (N, 3)`` to the body and the unit direction ``(N, 3)``
    that leads away from it (from the closest point, or the closest face's normal on the surface)."""
    dist, close, face = sdf.closest(points)
    d = points - close
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    direction = np.where(norm > 1e-6, d / np.maximum(norm, 1e-12), sdf.face_normals[face])
    direction = np.where(dist[:, None] < 0, -direction, direction)
    return dist.astype(np.float64), direction


def _smoothing_operator(num_verts: int, faces: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """Uniform averaging over neighbours ``(V, V)`` (boundary vertices average over their boundary
    neighbours) and the ``(V,)`` boundary mask."""
    edges, _, count = unique_edges(faces)
    on_border = np.zeros(num_verts, bool)
    on_border[edges[count == 1].reshape(-1)] = True
    # Row u takes edge (u, v) when u is interior, or when the edge itself is on the boundary.
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    use = ~on_border[rows] | np.tile(count == 1, 2)
    rows, cols = rows[use], cols[use]
    mat = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(num_verts, num_verts))
    deg = np.maximum(np.asarray(mat.sum(1)).reshape(-1), 1)
    return sp.diags(1.0 / deg) @ mat, on_border


def inflate(
    verts: np.ndarray,
    faces: np.ndarray,
    sdf: BodySDF,
    distance: np.ndarray,
    iterations: int = 30,
    rate: float = 0.5,
    frozen_z: np.ndarray | None = None,
) -> np.ndarray:
    """Lift a patch of the body surface to a smooth surface about ``distance`` above the body.

    Alternates Laplacian smoothing (which bridges folds such as the armpits) with pushing
    vertices closer than ``distance`` back out along the body's outward direction.

    Args:
        verts: ``(V, 3)`` patch vertices on the body, metres.
        faces: ``(F, 3)`` its triangles.
        sdf: the body.
        distance: ``(V,)`` wanted distance from the body (ease), metres.
        iterations: smoothing / push rounds.
        rate: smoothing step in ``(0, 1]``.
        frozen_z: ``(V,)`` bool, vertices that keep their height (a cut that another piece joins).

    Returns:
        ``(V, 3)`` float64 positions.
    """
    smooth, _ = _smoothing_operator(len(verts), faces)
    z0 = verts[:, 2].copy()
    p = verts + vertex_normals(verts, faces) * distance[:, None]
    for _ in range(iterations):
        p = p + rate * (smooth @ p - p)
        if frozen_z is not None:
            p[frozen_z, 2] = z0[frozen_z]
        d, direction = outward(sdf, p)
        push = np.maximum(distance - d, 0.0)
        p = p + direction * push[:, None]
        if frozen_z is not None:
            p[frozen_z, 2] = z0[frozen_z]
    return p


def push_out(
    verts: np.ndarray, faces: np.ndarray, sdf: BodySDF, clearance: float, iterations: int = 20
) -> np.ndarray:
    """Move vertices so that every vertex and edge midpoint is at least ``clearance`` (metres)
    outside the body, then relax the moved region a little. Returns ``(V, 3)`` float64."""
    verts = np.asarray(verts, dtype=np.float64).copy()
    edges, _, _ = unique_edges(faces)
    smooth, on_border = _smoothing_operator(len(verts), faces)
    goal = 1.3 * clearance
    for it in range(iterations):
        d, direction = outward(sdf, verts)
        mid = 0.5 * (verts[edges[:, 0]] + verts[edges[:, 1]])
        dm, dir_m = outward(sdf, mid)
        if d.min() >= clearance and dm.min() >= clearance:
            break
        move = np.where(d < goal, goal - d, 0.0)[:, None] * direction
        bad = np.nonzero(dm < goal)[0]
        for k in (0, 1):
            np.add.at(move, edges[bad, k], (goal - dm[bad])[:, None] * dir_m[bad])
        verts += move
        if it < iterations - 1:
            # Relax the neighbourhood of what moved so that no dent is left behind.
            moved = np.linalg.norm(move, axis=1) > 0
            near = (moved | (np.asarray(smooth[:, moved].sum(1)).reshape(-1) > 0)) & ~on_border
            verts[near] += 0.5 * (smooth @ verts - verts)[near]
    return verts


def orient_outward(verts: np.ndarray, faces: np.ndarray, sdf: BodySDF) -> np.ndarray:
    """``faces (F, 3)``, all flipped if most of the (area-weighted) normals point at the body."""
    tri = verts[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centroid = tri.mean(1)
    _, close, _ = sdf.closest(centroid)
    return faces if np.einsum("ij,ij->i", normal, centroid - close).sum() >= 0 else faces[:, ::-1].copy()


#: The bounded push's slack beyond a vertex's own depth, m.
PUSH_MARGIN = 0.001


def push_out_bounded(
    verts: np.ndarray, faces: np.ndarray, sdf: BodySDF, clearance: float, iterations: int = 4,
    margin: float = PUSH_MARGIN,
) -> tuple[np.ndarray, np.ndarray]:
    """Move vertices out of the body to ``clearance`` (m), each by at most its own depth.

    A vertex's depth is how far it, or the midpoint of an edge it ends, is short of ``clearance`` from the
    body (``clearance - signed distance``); it moves along the body's outward direction at the deepest of
    those points by that much, and in all (over ``iterations`` rounds, as the midpoints follow) never more
    than its first depth plus ``margin``. Vertices at the clearance already do not move, and nothing is
    smoothed afterwards (smoothing pulls moved vertices back in, and the next push moves them and their
    neighbours further: the unbounded :func:`push_out` moves a 6 mm dent by 31 mm).

    Returns:
        ``(verts (V, 3) float64, moved (V,) float64 distance each vertex moved, m)``.
    """
    start = np.asarray(verts, dtype=np.float64)
    verts = start.copy()
    edges, _, _ = unique_edges(faces)
    cap = None
    for _ in range(iterations):
        d, direction = outward(sdf, verts)
        dm, dir_m = outward(sdf, 0.5 * (verts[edges[:, 0]] + verts[edges[:, 1]]))
        short = np.concatenate([clearance - d, clearance - dm, clearance - dm])
        index = np.concatenate([np.arange(len(verts)), edges[:, 0], edges[:, 1]])
        dirs = np.concatenate([direction, dir_m, dir_m])
        order = np.argsort(short, kind="stable")  # the deepest written last: it wins each vertex
        need = np.zeros(len(verts))
        way = np.zeros_like(verts)
        need[index[order]] = short[order]
        way[index[order]] = dirs[order]
        need = np.maximum(need, 0.0)
        if cap is None:
            cap = np.where(need > 0, need + margin, 0.0)
        if not (need > 1e-6).any():
            break
        verts = verts + need[:, None] * way
        step = verts - start
        length = np.linalg.norm(step, axis=1)
        over = length > cap
        verts[over] = start[over] + step[over] * (cap[over] / length[over])[:, None]
    return verts, np.linalg.norm(verts - start, axis=1)
