"""Tubes: convex hull radius against a square, ring stitching against Euler's formula."""

import numpy as np

from loosefit.garment.mesh_checks import mesh_report
from loosefit.garment.tubes import MeshBuilder, build_tube, convex_radius, zip_rings


def test_convex_radius_of_a_square():
    square = np.array([[1.0, 1.0], [-1, 1], [-1, -1], [1, -1], [0.2, 0.1]])
    theta = np.linspace(0, 2 * np.pi, 73)
    r = convex_radius(square, np.zeros(2), theta, offset=0.5)
    exact = 1.5 / np.maximum(np.abs(np.cos(theta)), np.abs(np.sin(theta)))
    np.testing.assert_allclose(r, exact, rtol=1e-9)


def test_zip_rings_counts_and_orientation():
    top, bottom = np.arange(7), 7 + np.arange(11)
    tt = np.linspace(0, 2 * np.pi, 7, endpoint=False)
    tb = np.linspace(0, 2 * np.pi, 11, endpoint=False)
    tris = zip_rings(top, tt, bottom, tb)
    assert len(tris) == 18
    verts = np.concatenate([np.stack([np.cos(tt), np.sin(tt), np.ones(7)], 1), np.stack([np.cos(tb), np.sin(tb), np.zeros(11)], 1)])
    report = mesh_report(verts, tris)
    assert report.ok and report.num_boundary_loops == 2
    n = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]])
    centroid = verts[tris].mean(1)
    assert (np.einsum("ij,ij->i", n[:, :2], centroid[:, :2]) > 0).all()  # facing away from the axis


def test_build_tube_cone():
    builder = MeshBuilder()
    ang = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    top = builder.add_verts(np.stack([0.2 * np.cos(ang), 0.2 * np.sin(ang), np.ones(30)], 1))

    def cone(t, theta):
        r = 0.2 + 0.3 * t
        return np.stack([r * np.cos(theta), r * np.sin(theta), np.full_like(theta, 1.0 - 0.5 * t)], 1)

    hem, hem_theta = build_tube(builder, top, ang, cone, lambda t: np.zeros(2), 0.04, 0.58)
    verts, faces = builder.mesh()
    assert mesh_report(verts, faces).ok
    assert np.allclose(verts[hem, 2], 0.5) and abs(len(hem) - 2 * np.pi * 0.5 / 0.04) <= 1
