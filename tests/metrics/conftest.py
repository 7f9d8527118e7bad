"""Meshes of the metrics tests whose metrics are known in closed form."""

from __future__ import annotations

import numpy as np


def strip(n: int):
    """A flat strip of ``n`` unit squares along x in the plane z = 0, two triangles each: bottom vertices
    ``b_i = (i, 0, 0)`` (index i), top ``t_i = (i, 1, 0)`` (index n + 1 + i); square i holds
    ``(b_i, b_i+1, t_i+1)`` then ``(b_i, t_i+1, t_i)``. Its 2n - 1 interior edges: n diagonals and n - 1 rungs."""
    i = np.arange(n + 1)
    verts = np.concatenate([np.stack([i, 0 * i, 0 * i], 1), np.stack([i, 0 * i + 1, 0 * i], 1)]).astype(np.float64)
    b, t = np.arange(n), n + 1 + np.arange(n)
    faces = np.stack([np.stack([b, b + 1, t + 1], 1), np.stack([b, t + 1, t], 1)], 1).reshape(-1, 3)
    return verts, faces


def fold(verts: np.ndarray, at: float, degrees: float) -> np.ndarray:
    """``verts`` with everything beyond x = ``at`` turned by ``degrees`` about the line x = at, z = 0 (along y)."""
    a = np.radians(degrees)
    out = verts.copy()
    beyond = verts[:, 0] > at
    x = verts[beyond, 0] - at
    out[beyond, 0], out[beyond, 2] = at + x * np.cos(a), x * np.sin(a)
    return out


def sheet(half: float, n: int, z: float):
    """A flat square ``[-half, half]^2`` at height ``z``, ``n x n`` squares of two triangles each."""
    x = np.linspace(-half, half, n + 1)
    gx, gy = np.meshgrid(x, x, indexing="ij")
    verts = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)], 1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    faces = np.concatenate([np.stack([a, a + n + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + 1], 1)])
    return verts, faces


# A triangle across the unit box (half-width 0.5) in the plane z = 0.2, its centroid (0.1, 0.05, 0.2) 0.3 m deep
# (nearest face z = 0.5), its corners 1.05 m from the centroid at 0, 120 and 240 degrees: all three outside the
# box, two of its three edge midpoints inside.
CENTROID = np.array([0.1, 0.05, 0.2])
ANGLES = np.radians([0.0, 120.0, 240.0])
TRIANGLE = CENTROID + 1.05 * np.stack([np.cos(ANGLES), np.sin(ANGLES), 0 * ANGLES], 1)


def box_depth(points: np.ndarray) -> np.ndarray:
    """Depth ``(N,)`` of ``points (N, 3)`` inside the unit box centred at the origin, metres (negative outside)."""
    return (0.5 - np.abs(points)).min(-1)
