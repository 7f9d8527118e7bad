"""Tubes of vertex rings around a vertical axis, stitched ring to ring: the hanging parts of the
garments (skirts, shirt tails, trouser legs).

A tube is a surface ``S(t, theta)``: ``t`` in ``[0, 1]`` runs from its top ring down to its hem,
``theta`` is the polar angle around a vertical axis. Rings are sampled evenly in arc length at a
target edge length and neighbouring rings are zipped into triangles whose normals point away
from the axis.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.spatial import ConvexHull

TWO_PI = 2.0 * np.pi

#: ``surface(t, theta) -> (len(theta), 3)`` positions of a tube at height parameter ``t``.
Surface = Callable[[float, np.ndarray], np.ndarray]


def convex_radius(points: np.ndarray, center: np.ndarray, theta: np.ndarray, offset: float = 0.0) -> np.ndarray:
    """Radial function of the convex hull of 2D ``points``, grown by ``offset``.

    Args:
        points: ``(N, 2)`` points (x, y), metres, ``N >= 3``.
        center: ``(2,)`` a point inside their hull.
        theta: ``(K,)`` angles, radians (0 is +X, pi/2 is +Y).
        offset: outward offset of the hull's edges, metres.

    Returns:
        ``(K,)`` distance from ``center`` to the (offset) hull boundary along each angle.
    """
    eq = ConvexHull(points).equations  # n . x + c <= 0 inside, |n| = 1
    normal, c = eq[:, :2], eq[:, 2]
    u = np.stack([np.cos(theta), np.sin(theta)], 1)
    dot = u @ normal.T  # (K, E)
    dist = -(normal @ center + c) + offset  # (E,) distance from center to each offset edge line
    with np.errstate(divide="ignore"):
        r = np.where(dot > 1e-9, dist[None, :] / dot, np.inf)
    return r.min(1)


def polar(points: np.ndarray, center: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polar angle in ``[0, 2 pi)`` and radius of ``points (N, >=2)`` around ``center (2,)``."""
    d = points[:, :2] - center
    return np.mod(np.arctan2(d[:, 1], d[:, 0]), TWO_PI), np.linalg.norm(d, axis=1)


def periodic_interp(theta: np.ndarray, theta_known: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Interpolate a 2 pi periodic function known at ``theta_known`` (any order) at ``theta``."""
    order = np.argsort(theta_known)
    tk, vk = theta_known[order], values[order]
    tk = np.concatenate([tk[-1:] - TWO_PI, tk, tk[:1] + TWO_PI])
    vk = np.concatenate([vk[-1:], vk, vk[:1]], axis=0)
    return np.interp(np.mod(theta, TWO_PI), tk, vk) if vk.ndim == 1 else np.stack(
        [np.interp(np.mod(theta, TWO_PI), tk, vk[:, k]) for k in range(vk.shape[1])], 1
    )


def even_angles(surface: Surface, t: float, edge_length: float, anchors: tuple[float, ...]) -> np.ndarray:
    """Angles of a ring at ``t``, about ``edge_length`` apart in arc length, with a vertex at each
    of the increasing ``anchors`` (radians, spanning less than 2 pi) and at least 8 in all."""
    anchors = np.asarray(anchors, dtype=np.float64)
    ends = np.append(anchors, anchors[0] + TWO_PI)
    per_piece = max(2, int(np.ceil(8 / len(anchors))))
    out = []
    for lo, hi in zip(ends[:-1], ends[1:]):
        dense = np.linspace(lo, hi, 361)
        p = surface(t, dense)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        n = max(per_piece, int(round(arc[-1] / edge_length)))
        out.append(np.interp(np.arange(n) * arc[-1] / n, arc, dense))
    return np.concatenate(out)


def zip_rings(top: np.ndarray, top_theta: np.ndarray, bottom: np.ndarray, bottom_theta: np.ndarray) -> np.ndarray:
    """Triangles joining two closed rings of vertex ids, both ordered by increasing angle.

    ``top`` lies above ``bottom``; the triangles face away from the axis. Each ring's angles are
    taken relative to its first vertex's angle (the first vertices of both rings face each other).

    Returns:
        ``(len(top) + len(bottom), 3)`` int64 triangles.
    """
    ta = np.unwrap(top_theta)
    tb = np.unwrap(bottom_theta)
    ta = np.append(ta, ta[0] + TWO_PI)
    tb = np.append(tb, tb[0] + TWO_PI)
    na, nb = len(top), len(bottom)
    i = j = 0
    tris = []
    while i < na or j < nb:
        advance_top = j == nb or (i < na and ta[i + 1] - ta[0] <= tb[j + 1] - tb[0])
        if advance_top:
            tris.append((top[i % na], bottom[j % nb], top[(i + 1) % na]))
            i += 1
        else:
            tris.append((top[i % na], bottom[j % nb], bottom[(j + 1) % nb]))
            j += 1
    return np.array(tris, dtype=np.int64)


class MeshBuilder:
    """Accumulates vertices and triangles of a garment built from pieces."""

    def __init__(self, verts: np.ndarray | None = None, faces: np.ndarray | None = None):
        self.verts = [np.zeros((0, 3))] if verts is None else [np.asarray(verts, dtype=np.float64)]
        self.faces = [np.zeros((0, 3), np.int64)] if faces is None else [np.asarray(faces, dtype=np.int64)]
        self.count = len(self.verts[0])

    def add_verts(self, points: np.ndarray) -> np.ndarray:
        """Append ``(N, 3)`` points; returns their ids."""
        ids = self.count + np.arange(len(points))
        self.verts.append(np.asarray(points, dtype=np.float64))
        self.count += len(points)
        return ids

    def add_faces(self, faces: np.ndarray) -> None:
        self.faces.append(np.asarray(faces, dtype=np.int64))

    def position(self, ids: np.ndarray) -> np.ndarray:
        return np.concatenate(self.verts)[ids]

    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """``(verts (V, 3), faces (F, 3))`` built so far."""
        return np.concatenate(self.verts), np.concatenate(self.faces)


def build_tube(
    builder: MeshBuilder,
    top_ids: np.ndarray,
    top_theta: np.ndarray,
    surface: Surface,
    center: Callable[[float], np.ndarray],
    edge_length: float,
    length: float,
    anchors: tuple[float, ...] = (0.0,),
    last_anchors: tuple[float, ...] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Grow a tube below an existing ring of vertices.

    Args:
        builder: where the vertices and triangles go.
        top_ids: ids of the existing top ring, ordered by increasing angle.
        top_theta: their angles around the axis at ``t = 0``.
        surface: the tube's surface ``S(t, theta)``; ``S(0, .)`` should pass near the top ring.
        center: ``center(t) -> (2,)`` the axis (x, y) at ``t``, for the angles of new rings.
        edge_length: target spacing of vertices, metres.
        length: approximate length of the tube from top to hem, metres (sets the ring count).
        anchors: angles that get a vertex on every new ring (the first one starts each ring).
        last_anchors: the same for the hem ring (default ``anchors``).

    Returns:
        ids and angles of the hem ring.
    """
    rings = max(2, int(np.ceil(length / (0.87 * edge_length))))
    ids, theta = np.asarray(top_ids), np.asarray(top_theta)
    for k in range(1, rings + 1):
        t = k / rings
        ang = even_angles(surface, t, edge_length, last_anchors if k == rings and last_anchors else anchors)
        new = builder.add_verts(surface(t, ang))
        new_theta = polar(builder.position(new), center(t))[0]
        # Start the zip at the top vertex facing the new ring's first vertex.
        shift = int(np.argmin(np.abs(np.angle(np.exp(1j * (theta - new_theta[0]))))))
        builder.add_faces(zip_rings(np.roll(ids, -shift), np.roll(theta, -shift), new, new_theta))
        ids, theta = new, new_theta
    return ids, theta
