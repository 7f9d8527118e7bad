"""Mesh checks on small meshes whose answers are known by hand."""

import numpy as np

from loosefit.garment.mesh_checks import boundary_loops, mesh_report, nonmanifold_vertices, triangle_angles, unique_edges

# A unit square split into two triangles, and a closed tetrahedron.
SQUARE_V = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]])
TET_V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def test_edges_and_loops():
    edges, face_edge, count = unique_edges(SQUARE_F)
    assert edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    assert count.tolist() == [1, 2, 1, 1, 1]
    assert edges[face_edge[1, 0]].tolist() == [0, 2]
    (loop,) = boundary_loops(SQUARE_F)
    assert np.roll(loop, -int(np.argmin(loop))).tolist() == [0, 1, 2, 3]  # follows the faces
    assert boundary_loops(TET_F) == []


def test_report_of_good_meshes():
    for v, f, loops in ((SQUARE_V, SQUARE_F, 1), (TET_V, TET_F, 0)):
        r = mesh_report(v, f)
        assert r.ok and r.num_boundary_loops == loops and r.num_components == 1
    np.testing.assert_allclose(np.sort(triangle_angles(SQUARE_V, SQUARE_F)[0]), [45, 45, 90])


def test_report_of_broken_meshes():
    r = mesh_report(SQUARE_V, np.array([[0, 1, 2], [0, 3, 2]]))  # second face flipped
    assert not r.ok and r.misoriented_edges == [[2, 0]]  # the half edge both faces run along
    r = mesh_report(np.vstack([SQUARE_V, [[0, 0, 1]]]), np.array([[0, 1, 2], [0, 2, 3], [0, 2, 4]]))
    assert not r.ok and r.nonmanifold_edges == [[0, 2]]
    r = mesh_report(SQUARE_V, np.array([[0, 1, 2], [0, 2, 3], [0, 1, 2], [1, 1, 3]]))
    assert r.duplicate_faces == [2] and r.degenerate_faces == [3]
    bowtie_v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]])
    bowtie_f = np.array([[0, 1, 2], [0, 3, 4]])
    assert nonmanifold_vertices(5, bowtie_f).tolist() == [0]
    r = mesh_report(np.vstack([bowtie_v, [[5.0, 5, 5]]]), bowtie_f)
    assert r.nonmanifold_verts == [0] and r.unreferenced_verts == [5] and not r.ok
    r = mesh_report(np.vstack([TET_V, TET_V + 3]), np.vstack([TET_F, TET_F + 4]))
    assert r.num_components == 2 and not r.ok
