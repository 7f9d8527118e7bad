"""Edge-graph Dijkstra against closed-form grid distances; heat method against flat-plane distances."""

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.geometry.geodesic import HeatGeodesics, edge_geodesics
from tests.geometry.test_laplacian import grid


def test_dijkstra_on_grid_equals_closed_form_path_length():
    n, h = 6, 0.1
    verts, faces = grid(n, h)
    d = edge_geodesics(verts, faces, sources=[0])[0]
    a, b = np.divmod(np.arange(len(verts)), n + 1)
    # Edges run along x, along y and along the (+1, +1) diagonal.
    expected = h * (np.abs(a - b) + np.sqrt(2) * np.minimum(a, b))
    assert d.dtype == np.float32 and np.abs(d - expected).max() < 1e-6


def test_full_matrix_is_symmetric_and_components_are_infinitely_apart():
    verts, faces = grid(2, 1.0)
    second = verts + [10, 0, 0]
    v = np.vstack([verts, second])
    f = np.vstack([faces, faces + len(verts)])
    D = edge_geodesics(v, f)
    assert D.shape == (18, 18) and np.allclose(D, D.T) and np.allclose(np.diag(D), 0)
    assert np.isinf(D[0, 9:]).all() and np.isfinite(D[:9, :9]).all()


def test_heat_method_approximates_planar_distance():
    n = 40
    verts, faces = grid(n, 1.0 / n)
    centre = (n // 2) * (n + 1) + n // 2
    d = HeatGeodesics(verts, faces).distances([centre, 0])
    assert d.shape == (2, len(verts))
    true = np.linalg.norm(verts - verts[centre], axis=1)
    far = true > 0.1
    assert np.abs(d[0][far] - true[far]).max() / true[far].max() < 0.05
    # The edge-graph distance is an upper bound of the surface distance.
    assert (edge_geodesics(verts, faces, [centre])[0] >= true - 1e-6).all()


def test_bad_sources_are_rejected():
    verts, faces = grid(2)
    with pytest.raises(InputError, match="outside"):
        edge_geodesics(verts, faces, [99])
    with pytest.raises(InputError, match="indices"):
        HeatGeodesics(verts, faces).distances([0.5])
