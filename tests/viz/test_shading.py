"""Vertex normals and the two-sided Lambert brightness against brute force and closed form."""

from __future__ import annotations

import numpy as np

from loosefit.geometry.normals import face_cross
from loosefit.viz.shading import AMBIENT, DIFFUSE, LIGHTS, VertexNormals, lambert


def octahedron():
    verts = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float32)
    faces = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return verts, faces


def test_vertex_normals_match_brute_force_and_symmetry():
    verts, faces = octahedron()
    rng = np.random.default_rng(1)
    warped = verts * rng.uniform(0.5, 1.5, (1, 3)).astype(np.float32)
    normals = VertexNormals(faces, 7)  # vertex 6 is isolated
    padded = np.vstack([warped, [[9, 9, 9]]]).astype(np.float32)
    got = normals(padded)
    brute = np.zeros((7, 3))
    for f, n in zip(faces, face_cross(padded, faces)):
        brute[f] += n
    brute[:6] /= np.linalg.norm(brute[:6], axis=1, keepdims=True)
    brute[6] = (0, 0, 1)
    np.testing.assert_allclose(got, brute, atol=1e-6)
    # By symmetry the octahedron's vertex normals point along its axes, outwards.
    np.testing.assert_allclose(normals(np.vstack([verts, [[0, 0, 0]]]))[:6], verts, atol=1e-6)


def test_lambert_two_sided_closed_form():
    basis = np.eye(3)  # camera axes = world axes: lights are given in these coordinates
    normal = np.array([[0.0, 0.0, 1.0]])
    to_eye = np.array([[0.0, 0.0, 1.0]])
    expected = AMBIENT + DIFFUSE * sum(i * d[2] / np.linalg.norm(d) for d, i in LIGHTS)
    np.testing.assert_allclose(lambert(normal, to_eye, basis), [expected])
    # A back face seen from the eye is lit as its front (open garments show their inside).
    np.testing.assert_allclose(lambert(-normal, to_eye, basis), [expected])
    # A surface facing away from every light gets the ambient term only.
    np.testing.assert_allclose(lambert(-normal, -to_eye, basis), [AMBIENT])
