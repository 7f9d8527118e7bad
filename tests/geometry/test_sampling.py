"""Furthest point sampling against a brute-force reference."""

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.geometry.geodesic import edge_geodesics
from loosefit.geometry.sampling import furthest_point_sampling
from tests.geometry.test_laplacian import grid


def brute_force_fps(dist, count, start):
    chosen = [start]
    while len(chosen) < count:
        score = [min(dist[c][i] for c in chosen) if i not in chosen else -1 for i in range(len(dist))]
        chosen.append(int(np.argmax(score)))
    return chosen


def test_points_on_a_line():
    pts = np.stack([np.arange(11.0), np.zeros(11), np.zeros(11)], 1)
    assert furthest_point_sampling(pts, 3, start=0).tolist() == [0, 10, 5]


def test_euclidean_matches_brute_force_and_seed_picks_start():
    pts = np.random.default_rng(0).uniform(-1, 1, (60, 3))
    dist = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    got = furthest_point_sampling(pts, 12, start=7)
    assert got.tolist() == brute_force_fps(dist, 12, 7)
    a, b = furthest_point_sampling(pts, 5, seed=3), furthest_point_sampling(pts, 5, seed=3)
    assert np.array_equal(a, b) and a[0] == np.random.default_rng(3).integers(60)


def test_geodesic_matches_brute_force_on_a_folded_strip():
    verts, faces = grid(8, 0.1)
    # Fold the sheet along x = 0.4 so that Euclidean and geodesic neighbours differ.
    x = verts[:, 0]
    folded = verts.copy()
    folded[x > 0.4, 0] = 0.8 - x[x > 0.4]
    folded[x > 0.4, 2] = 0.05
    geo = edge_geodesics(folded, faces)
    got = furthest_point_sampling(folded, 10, faces=faces, start=0)
    assert got.tolist() == brute_force_fps(geo, 10, 0)
    assert got.tolist() != furthest_point_sampling(folded, 10, start=0).tolist()


def test_count_limits_and_distinct_samples():
    pts = np.zeros((4, 3))  # all coincident: still four distinct indices
    assert sorted(furthest_point_sampling(pts, 4, start=2).tolist()) == [0, 1, 2, 3]
    with pytest.raises(InputError, match="count"):
        furthest_point_sampling(pts, 5)
    with pytest.raises(InputError, match="start"):
        furthest_point_sampling(pts, 2, start=4)
