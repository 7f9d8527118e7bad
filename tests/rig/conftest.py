"""Fixtures of the rig tests: a small simulated skirt and small synthetic meshes."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="session")
def simulated_skirt(body):
    """A ~600-vertex flared skirt simulated (Blender cloth) on a 1.5 s spin: garment, ``(45, V, 3)`` frames, motion."""
    from loosefit.garment import make_garment
    from loosefit.motion.procedural import generate
    from loosefit.sim import SimParams, simulate_sequence

    garment = make_garment("skirt", body, seed=3, edge_length=0.045, flare=25.0, length=0.55)
    motion = generate("spin", 1.5, 0, body)
    result = simulate_sequence(garment, body, motion, SimParams(preroll=0.5))
    assert np.isfinite(result.verts).all()
    return garment, result.verts, motion


def tube(rings: int = 12, around: int = 24, radius: float = 0.2, height: float = 0.6):
    """An open cylinder along Z: ``rings * around`` vertices, consistently oriented triangles."""
    z = np.linspace(0.0, height, rings)
    a = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
    x, y, z = np.broadcast_arrays(radius * np.cos(a)[None], radius * np.sin(a)[None], z[:, None])
    verts = np.stack([x, y, z], -1).reshape(-1, 3)
    faces = []
    for i in range(rings - 1):
        for j in range(around):
            p, q = i * around + j, i * around + (j + 1) % around
            faces += [(p, q, q + around), (p, q + around, p + around)]
    return verts.astype(np.float64), np.array(faces, np.int64)


def sheet(nx: int, ny: int, width: float = 1.0, height: float = 0.8, jitter: float = 0.0, seed: int = 0):
    """A flat rectangle in the XY plane triangulated on an ``nx x ny`` grid; interior vertices moved
    by up to ``jitter`` grid steps (a different triangulation of the same surface)."""
    x, y = np.meshgrid(np.linspace(0, width, nx), np.linspace(0, height, ny))
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(nx * ny)], 1)
    inner = (verts[:, 0] > 0) & (verts[:, 0] < width) & (verts[:, 1] > 0) & (verts[:, 1] < height)
    step = np.array([width / (nx - 1), height / (ny - 1)])
    verts[inner, :2] += np.random.default_rng(seed).uniform(-jitter, jitter, (inner.sum(), 2)) * step
    i, j = np.meshgrid(np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
    a = (i * nx + j).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + nx], 1), np.stack([a + 1, a + nx + 1, a + nx], 1)])
    return verts, faces.astype(np.int64)


def hex_sheet(width: float = 1.0, height: float = 0.8, h: float = 0.025, jitter: float = 0.15, seed: int = 0):
    """A flat rectangle-like sheet in the XY plane of near-equilateral triangles (edge ``h``, rows of a
    hexagonal lattice, odd rows shifted by ``h / 2``), as the garment remesher makes them; interior vertices
    moved by up to ``jitter * h``. Returns ``verts (N, 3)`` float64 and ``faces (F, 3)`` int64."""
    n, rows = int(round(width / h)) + 1, int(round(height / (h * np.sqrt(3) / 2))) + 1
    i, j = np.meshgrid(np.arange(n), np.arange(rows))
    x = i * h + 0.5 * h * (j % 2)
    y = j * h * np.sqrt(3) / 2
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(n * rows)], 1).astype(np.float64)
    inner = ((i > 0) & (i < n - 1) & (j > 0) & (j < rows - 1)).ravel()
    verts[inner, :2] += np.random.default_rng(seed).uniform(-jitter, jitter, (inner.sum(), 2)) * h
    faces = []
    for r in range(rows - 1):
        a, b = r * n, (r + 1) * n  # first vertex of this row and of the next
        for k in range(n - 1):
            if r % 2 == 0:  # the next row is shifted right
                faces += [(a + k, a + k + 1, b + k), (b + k, a + k + 1, b + k + 1)]
            else:  # this row is shifted right
                faces += [(a + k, b + k + 1, b + k), (a + k, a + k + 1, b + k + 1)]
    return verts, np.array(faces, np.int64)
