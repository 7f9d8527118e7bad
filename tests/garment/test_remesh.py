"""Isotropic remeshing of an open cylinder: topology kept, edges at the target, vertices on the surface."""

import numpy as np
import pytest

from loosefit.garment.mesh_checks import boundary_loops, face_areas, mesh_report, triangle_angles, unique_edges
from loosefit.garment.remesh import ReferenceSurface, remesh


def cylinder(n=40, rings=5, radius=0.3, height=0.6):
    theta = np.linspace(0, 2 * np.pi, n, endpoint=False)
    verts = np.array([[radius * np.cos(t), radius * np.sin(t), z] for z in np.linspace(0, height, rings) for t in theta])
    faces = []
    for i in range(rings - 1):
        for j in range(n):
            a, b = i * n + j, i * n + (j + 1) % n
            faces += [[a, b, b + n], [a, b + n, a + n]]
    return verts, np.array(faces)


@pytest.mark.parametrize("h", [0.05, 0.02])
def test_remesh_cylinder(h):
    verts, faces = cylinder()  # long thin input triangles (0.047 x 0.15 m)
    out_v, out_f = remesh(verts, faces, h)
    report = mesh_report(out_v, out_f)
    assert report.ok and report.num_boundary_loops == 2
    edges, _, _ = unique_edges(out_f)
    length = np.linalg.norm(out_v[edges[:, 0]] - out_v[edges[:, 1]], axis=1)
    assert 0.9 * h < length.mean() < 1.1 * h
    assert triangle_angles(out_v, out_f).min() > 20
    # Vertices stay on the input surface, boundary vertices on its two rims.
    surface = ReferenceSurface(verts, faces, spacing=h / 20)
    np.testing.assert_allclose(surface.project(out_v), out_v, atol=1e-9)
    for loop in boundary_loops(out_f):
        z = out_v[loop, 2]
        assert np.allclose(z, 0.0, atol=1e-9) or np.allclose(z, 0.6, atol=1e-9)
    np.testing.assert_allclose(face_areas(out_v, out_f).sum(), face_areas(verts, faces).sum(), rtol=0.01)
