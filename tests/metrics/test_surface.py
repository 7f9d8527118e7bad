"""E_dist, E_norm and Laplacian consistency against hand-built cases and libigl; the collapsed share and
roughness against strips of known folds."""

import numpy as np
import pytest
import trimesh

from loosefit.errors import InputError
from loosefit.geometry.laplacian import cotangent_laplacian
from loosefit.metrics.surface import (
    bend_ratio,
    collapsed_faces,
    collapsed_pct,
    dihedral_angles_deg,
    e_dist_cm,
    e_norm_deg,
    face_normal_deviation_deg,
    interior_edges,
    laplacian_consistency,
    mean_laplacian_consistency,
    roughness_deg,
    roughness_per_edge_deg,
)
from tests.metrics.conftest import fold, strip

TRI = np.array([[0, 1, 2]])


def test_e_dist_is_mean_distance_in_cm():
    gt = np.zeros((1, 2, 3))
    pred = np.array([[[0.01, 0, 0], [0, 0.03, 0]]])
    assert e_dist_cm(pred, gt) == pytest.approx(2.0)


@pytest.mark.parametrize("theta", [1e-3, 0.3, 1.2, np.pi - 1e-4])
def test_e_norm_of_a_tilted_triangle(theta):
    gt = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=np.float64)
    pred = gt.copy()
    pred[0, 2] = [0, np.cos(theta), np.sin(theta)]  # turn the triangle by theta about the x axis
    assert e_norm_deg(pred, gt, TRI) == pytest.approx(np.degrees(theta), rel=1e-5)


def test_e_norm_averages_faces_and_skips_degenerate_ones():
    gt = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 0, 0]]], dtype=np.float64)
    faces = np.array([[0, 1, 2], [1, 3, 2], [0, 1, 4]])  # the last one is a degenerate sliver
    pred = gt.copy()
    pred[0, 3, 2] = 1.0  # lifts the corner only the second face uses
    n = np.cross(pred[0, 3] - pred[0, 1], pred[0, 2] - pred[0, 1])
    tilt = np.degrees(np.arccos(n[2] / np.linalg.norm(n)))
    dev = face_normal_deviation_deg(pred, gt, faces)
    assert dev[0, 0] == pytest.approx(0.0, abs=1e-6) and dev[0, 1] == pytest.approx(tilt) and np.isnan(dev[0, 2])
    assert e_norm_deg(pred, gt, faces) == pytest.approx(tilt / 2)


def test_laplacian_consistency_against_libigl_diagonals():
    m = trimesh.creation.icosphere(2)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    rng = np.random.default_rng(0)
    after = v + rng.normal(0, 0.02, v.shape)
    ref = np.abs(cotangent_laplacian(after, f).diagonal() - cotangent_laplacian(v, f).diagonal())
    d = laplacian_consistency(v, after, f)
    assert d.shape == (len(v),) and np.abs(d - ref).max() < 1e-10
    assert np.abs(laplacian_consistency(v, 3.0 * v, f)).max() < 1e-10  # cotangents are scale invariant
    sel = [0, 5, 17]
    assert mean_laplacian_consistency(v, after, f, sel) == pytest.approx(ref[sel].mean())
    mask = np.zeros(len(v), bool)
    mask[sel] = True
    seq = np.stack([v, v])
    assert mean_laplacian_consistency(seq, np.stack([after, v]), f, mask) == pytest.approx(ref[sel].mean() / 2)
    assert mean_laplacian_consistency(v, after, f) == pytest.approx(ref.mean())
    with pytest.raises(InputError, match="empty"):
        mean_laplacian_consistency(v, after, f, np.zeros(len(v), bool))


def test_interior_edges_of_a_strip():
    verts, faces = strip(4)
    edge, pair = interior_edges(faces)
    assert len(edge) == 2 * 4 - 1 and (edge[:, 0] < edge[:, 1]).all()
    for (i, j), (f, g) in zip(edge, pair):  # both triangles hold the edge, no third does
        holders = [k for k, tri in enumerate(faces) if i in tri and j in tri]
        assert holders == [f, g]
    assert len(interior_edges(TRI)[0]) == 0


def test_one_flipped_triangle_in_a_strip_of_n():
    """t_0 lies in the second triangle only; mirrored across that triangle's diagonal b_0-t_1 it keeps its area
    and turns the triangle over: 1 of the N = 2n triangles."""
    n = 5
    gt, faces = strip(n)
    pred = gt.copy()
    pred[n + 1] = [1.0, 0.0, 0.0]  # t_0 = (0, 1, 0) mirrored across the line through (0, 0) and (1, 1)
    mask = collapsed_faces(pred, gt, faces)
    assert mask.shape == (1, 2 * n) and mask[0].tolist() == [False, True] + [False] * (2 * n - 2)
    assert collapsed_pct(pred, gt, faces) == pytest.approx(100.0 / (2 * n))
    # two frames, the flip in one of them: half as much
    assert collapsed_pct(np.stack([pred, gt]), np.stack([gt, gt]), faces) == pytest.approx(100.0 / (4 * n))


def test_shrunk_and_degenerate_triangles_count_without_a_nan():
    n = 3
    gt, faces = strip(n)
    degenerate = gt.copy()
    degenerate[n + 1] = [0.5, 0.5, 0.0]  # t_0 onto the diagonal b_0-t_1: the second triangle has no area
    assert collapsed_pct(degenerate, gt, faces) == pytest.approx(100.0 / (2 * n))
    rough = roughness_per_edge_deg(degenerate, gt, faces)
    assert np.isfinite(rough).all() and np.isfinite(roughness_deg(degenerate, gt, faces))
    point = np.zeros_like(gt)  # everything on one point: every triangle collapsed, angles still finite
    assert collapsed_pct(point, gt, faces) == 100.0 and np.isfinite(roughness_deg(point, gt, faces))
    assert collapsed_pct(point, point, faces) == 0.0  # nothing to collapse from
    # a triangle at 19 % of its area has collapsed, one at 21 % has not: scale t_0 toward b_0 (area ~ distance)
    for share, collapsed in ((0.19, True), (0.21, False)):
        small = gt.copy()
        small[n + 1] = gt[0] + share * (gt[n + 1] - gt[0])
        assert collapsed_faces(small, gt, faces)[0, 1] == collapsed


def test_roughness_of_a_fold_along_one_interior_edge():
    """Folding the strip by a along the rung x = 2 turns only that edge's dihedral angle, to a: the mean over the
    2n - 1 interior edges is a / (2n - 1). The other way it is -a, so against a fold of a it is 2a off."""
    n = 4
    flat, faces = strip(n)
    edge, pair = interior_edges(faces)
    for a in (30.0, 90.0, 150.0):
        folded = fold(flat, 2.0, a)
        angles = dihedral_angles_deg(folded, faces, edge, pair)
        rung = (edge == [2, n + 1 + 2]).all(1)
        assert np.abs(angles[rung]) == pytest.approx([a]) and np.abs(angles[~rung]).max() < 1e-9
        assert roughness_deg(folded, flat, faces) == pytest.approx(a / (2 * n - 1))
        assert roughness_deg(flat, folded, faces) == pytest.approx(a / (2 * n - 1))
        other_way = fold(flat, 2.0, -a)
        assert roughness_deg(other_way, folded, faces) == pytest.approx(min(2 * a, 360 - 2 * a) / (2 * n - 1))


def test_bend_ratio_of_folds_of_known_angles():
    """One rung folded by a in the prediction and by b in the simulation: a / b, whichever way each folds (the
    unsigned angles); over two frames, the ratio of the sums. Flat in both: None."""
    n = 4
    flat, faces = strip(n)
    for a, b in ((30.0, 60.0), (90.0, 45.0), (150.0, 150.0)):
        pred, gt = fold(flat, 2.0, a), fold(flat, 2.0, -b)
        assert bend_ratio(pred, gt, faces) == pytest.approx(a / b)
        # two frames: the ratio of the sums, not the mean of the frames' ratios
        two = bend_ratio(np.stack([pred, flat]), np.stack([gt, fold(flat, 1.0, 10.0)]), faces)
        assert two == pytest.approx(a / (b + 10.0))
    assert bend_ratio(flat, flat, faces) is None


def test_identical_and_rigidly_moved_meshes_score_zero():
    m = trimesh.creation.icosphere(2)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    rng = np.random.default_rng(1)
    gt = np.stack([v + rng.normal(0, 0.02, v.shape) for _ in range(3)])
    assert collapsed_pct(gt, gt, f) == 0.0 and roughness_deg(gt, gt, f) == 0.0
    turn = trimesh.transformations.rotation_matrix(0.7, [1, 2, 3])[:3, :3]
    moved = gt @ turn.T + [0.3, -1.0, 2.0]
    assert collapsed_pct(moved, gt, f) == 0.0 and roughness_deg(moved, gt, f) < 1e-6
    assert bend_ratio(gt, gt, f) == 1.0 and bend_ratio(moved, gt, f) == pytest.approx(1.0, abs=1e-9)
    with pytest.raises(InputError, match="no edge shared"):
        roughness_deg(gt[:, :3], gt[:, :3], TRI)
