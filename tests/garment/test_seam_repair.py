"""Seam repairs on small meshes whose answers are known by hand."""

import numpy as np

from loosefit.garment.mesh_checks import mesh_report, unique_edges
from loosefit.garment.seam_repair import slivers, split_nonmanifold, weld

# Edge a-b with three pages: c1 and c2 continue each other flat, c3 stands at 90 degrees.
BOOK_V = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]])
BOOK_F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])


def test_three_pages_keep_the_flat_pair_glued():
    verts, faces, counts = split_nonmanifold(BOOK_V, BOOK_F)
    assert counts == {"nonmanifold_edges": 1, "split_vertices": 2}
    assert faces[:2].tolist() == BOOK_F[:2].tolist()  # the flat pair keeps the shared edge
    assert sorted(faces[2, :2].tolist()) == [5, 6] and faces[2, 2] == 4  # the standing page gets copies of a, b
    np.testing.assert_array_equal(verts[faces[2, :2]], BOOK_V[[0, 1]])
    assert unique_edges(faces)[2].max() == 2 and not mesh_report(verts, faces).nonmanifold_verts


def test_four_pages_pair_up_by_opening_angle():
    # Pages at 0, 100, 180 and 280 degrees around the x axis: 0-180 and 100-280 are flat pairs.
    ang = np.radians([0.0, 100.0, 180.0, 280.0])
    verts = np.vstack([[[0.0, 0, 0], [1, 0, 0]], np.stack([np.full(4, 0.5), np.cos(ang), np.sin(ang)], 1)])
    faces = np.array([[0, 1, 2], [0, 1, 3], [1, 0, 4], [1, 0, 5]])
    out_v, out_f, counts = split_nonmanifold(verts, faces)
    assert counts == {"nonmanifold_edges": 1, "split_vertices": 2}
    shared = lambda i, j: len(set(out_f[i, :2]) & set(out_f[j, :2]))  # noqa: E731
    assert shared(0, 2) == 2 and shared(1, 3) == 2 and shared(0, 1) == 0
    assert unique_edges(out_f)[2].max() == 2


def test_pinched_vertex_is_split():
    verts = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]])
    faces = np.array([[0, 1, 2], [0, 3, 4]])
    out_v, out_f, counts = split_nonmanifold(verts, faces)
    assert counts == {"nonmanifold_edges": 0, "split_vertices": 1}
    assert out_f.tolist() == [[0, 1, 2], [5, 3, 4]] and out_v[5].tolist() == [0.0, 0.0, 0.0]
    # A manifold mesh is left as it is.
    same_v, same_f, counts = split_nonmanifold(BOOK_V, BOOK_F[:2])
    assert counts["split_vertices"] == 0 and same_f.tolist() == BOOK_F[:2].tolist() and len(same_v) == 5


def test_weld_and_slivers():
    # Two panels of a square, written with their own copies of the seam vertices (1e-6 apart).
    verts = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 0, 1e-6], [1, 1, 1e-6], [0, 1, 0]])
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    out_v, out_f, merged = weld(verts, faces, 1e-4)
    assert merged == 2 and out_f.tolist() == [[0, 1, 2], [0, 2, 3]] and out_v.tolist() == verts[[0, 1, 2, 5]].tolist()
    assert weld(verts, faces, 1e-7)[2] == 0
    # A 6 x 6 sheet folded onto itself: the fold puts its interior vertex 7 (row 1, column 1) 1e-6 from the
    # interior vertex 10 (row 1, column 4). They are different points of the cloth: not welded.
    n = 6
    grid = np.array([[x, y, 0.0] for y in range(n) for x in range(n)])
    quads = [(r * n + c, r * n + c + 1, (r + 1) * n + c + 1, (r + 1) * n + c) for r in range(n - 1) for c in range(n - 1)]
    sheet = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    folded = grid.copy()
    folded[10] = folded[7] + [0.0, 0.0, 1e-6]
    assert weld(folded, sheet, 1e-4)[2] == 0
    # Two triangles folded flat about their common edge 0-1, their tips 2 and 3 1e-6 apart: merged, they would
    # be one face written twice.
    flap = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, 1, 1e-6]])
    assert weld(flap, np.array([[0, 1, 2], [1, 0, 3]]), 1e-4)[2] == 0
    # A collapsed edge (vertex 8 moved 1e-6 from its neighbour 7) is one point written twice: welded.
    collapsed = grid.copy()
    collapsed[8] = collapsed[7] + [1e-6, 0.0, 0.0]
    assert weld(collapsed, sheet, 1e-4)[2] == 1
    tri = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 2e-4, 0], [0.5, 1, 0]])
    # Height 2e-4 of a unit edge is below 1e-3 of it; height 1 is not.
    assert slivers(tri, np.array([[0, 1, 2], [0, 1, 3]])).tolist() == [True, False]
    assert slivers(tri, np.array([[0, 1, 2]]), ratio=1e-4).tolist() == [False]
