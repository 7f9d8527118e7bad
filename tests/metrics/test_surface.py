"""E_dist, E_norm and Laplacian consistency against hand-built cases and libigl."""

import numpy as np
import pytest
import trimesh

from loosefit.errors import InputError
from loosefit.geometry.laplacian import cotangent_laplacian
from loosefit.metrics.surface import (
    e_dist_cm,
    e_norm_deg,
    face_normal_deviation_deg,
    laplacian_consistency,
    mean_laplacian_consistency,
)

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
