"""Cutting a triangle mesh along the zero level set of a per-vertex scalar field."""

from __future__ import annotations

import numpy as np

from loosefit.garment.mesh_checks import unique_edges


def cut_mesh(
    verts: np.ndarray, faces: np.ndarray, phi: np.ndarray, attrs: np.ndarray | None = None, margin: float = 0.15
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Keep the part of a mesh where ``phi < 0``, cutting faces along the linearly interpolated
    zero crossing.

    Args:
        verts: ``(V, 3)`` positions.
        faces: ``(F, 3)`` int64 triangles.
        phi: ``(V,)`` scalar field; negative is kept.
        attrs: optional ``(V, K)`` per-vertex values, interpolated onto the new vertices.
        margin: crossings are kept at least this fraction of an edge away from its ends, so the cut
            makes no sliver triangles (the cut curve moves by at most that fraction of an edge).

    Returns:
        ``(verts, faces, attrs)`` of the kept part, unused vertices dropped; orientation preserved.
    """
    verts = np.asarray(verts, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    phi = np.asarray(phi, dtype=np.float64)
    inside = phi < 0
    edges, face_edge, _ = unique_edges(faces)
    crossing = inside[edges[:, 0]] != inside[edges[:, 1]]
    pa, pb = phi[edges[crossing, 0]], phi[edges[crossing, 1]]
    t = np.clip(pa / (pa - pb), margin, 1.0 - margin)[:, None]
    new_id = np.full(len(edges), -1)
    new_id[crossing] = len(verts) + np.arange(crossing.sum())
    ea, eb = edges[crossing, 0], edges[crossing, 1]
    verts = np.concatenate([verts, (1 - t) * verts[ea] + t * verts[eb]])
    if attrs is not None:
        attrs = np.asarray(attrs, dtype=np.float64)
        attrs = np.concatenate([attrs, (1 - t) * attrs[ea] + t * attrs[eb]])

    n_in = inside[faces].sum(1)
    out = [faces[n_in == 3]]
    for count in (1, 2):
        sel = np.nonzero(n_in == count)[0]
        if len(sel) == 0:
            continue
        # Rotate each face so that corner 0 is the odd one out (the lone inside or outside vertex).
        odd_inside = count == 1
        lone = np.argmax(inside[faces[sel]] == odd_inside, axis=1)
        k0, k1, k2 = lone, (lone + 1) % 3, (lone + 2) % 3
        f = faces[sel]
        i = np.arange(len(sel))
        v0, v1, v2 = f[i, k0], f[i, k1], f[i, k2]
        m01 = new_id[face_edge[sel, k0]]  # edge corner k0 -> k0 + 1
        m20 = new_id[face_edge[sel, k2]]  # edge corner k2 -> k0
        if odd_inside:
            out.append(np.stack([v0, m01, m20], 1))
        else:
            out += [np.stack([m01, v1, v2], 1), np.stack([m01, v2, m20], 1)]
    faces = np.concatenate(out)
    used = np.zeros(len(verts), bool)
    used[faces.reshape(-1)] = True
    remap = np.cumsum(used) - 1
    return verts[used], remap[faces], None if attrs is None else attrs[used]
