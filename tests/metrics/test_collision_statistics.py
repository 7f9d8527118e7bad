"""Penetration percentages and depths (:func:`loosefit.metrics.collision.penetration`) against brute force on
a sheet pushed into the unit box by a different amount each frame: per frame, the vertex share is the count of
vertices deeper than the tolerance over all vertices, the surface share the count of samples deeper than the
depth over all ``E + F`` samples (queried or not), and the deepest point the deepest vertex or sample."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from loosefit.geometry.laplacian import edges
from loosefit.metrics.collision import collision_ratio, collision_ratio_per_frame, penetration, surface_samples
from tests.metrics.conftest import box_depth, sheet

BOX = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
BV, BF = np.asarray(BOX.vertices), np.asarray(BOX.faces)


def frames() -> tuple[np.ndarray, np.ndarray]:
    """A tilted, rippled 1.6 m sheet, its low corner inside the box's top by 0 to 12 cm depending on the frame."""
    verts, faces = sheet(0.8, 8, 0.0)
    out = []
    for t, dip in enumerate((0.0, 0.03, 0.12, 0.06, 0.004)):
        v = verts.copy()
        v[:, 2] = 0.5 + 0.3 * (v[:, 0] + 0.8) / 1.6 + 0.02 * np.sin(7 * v[:, 1] + t) - dip
        v[:, 0] += 0.05 * t
        out.append(v)
    return np.stack(out), faces


def test_penetration_figures_against_brute_force():
    g, faces = frames()
    tol, depth = 0.002, 0.005
    got = penetration(g, faces, BV, BF, tolerance=tol, depth=depth)
    samples = surface_samples(g, faces)  # (T, E + F, 3)
    S = len(edges(faces)) + len(faces)
    assert got.samples == S == samples.shape[1]
    for t in range(len(g)):
        dv, ds = box_depth(g[t]), box_depth(samples[t])
        assert got.vertex_percent[t] == pytest.approx(100.0 * np.sum(dv > tol) / len(dv), abs=1e-9)
        assert got.surface_percent[t] == pytest.approx(100.0 * np.sum(ds > depth) / S, abs=1e-9)
        assert got.deepest_m[t] == pytest.approx(max(0.0, dv.max(), ds.max()), abs=1e-6)
    assert got.vertex_percent[0] == 0.0 < got.vertex_percent[2]  # frames differ
    assert len(set(np.round(got.surface_percent, 6))) >= 3
    per_frame = collision_ratio_per_frame(g, BV, BF, tolerance=tol)
    np.testing.assert_allclose(per_frame, got.vertex_percent, atol=1e-9)
    assert collision_ratio(g, BV, BF, tolerance=tol) == pytest.approx(per_frame.mean(), abs=1e-12)
