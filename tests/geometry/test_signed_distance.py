"""BodySDF against the closed form of a sphere and against libigl's own signed distance."""

import igl
import numpy as np
import pytest
import trimesh

from loosefit.errors import InputError
from loosefit.geometry.signed_distance import BodySDF


@pytest.fixture(scope="module")
def sphere():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def test_sphere_distance_is_radius_offset(sphere):
    verts, faces = sphere
    sdf = BodySDF(verts, faces)
    rng = np.random.default_rng(0)
    points = rng.normal(size=(2000, 3)) * rng.uniform(0.1, 2.0, (2000, 1))
    dist = sdf.query(points)
    exact = np.linalg.norm(points, axis=1) - 1.0
    # A subdivision-4 icosphere lies within 1.3 mm of the unit sphere.
    assert dist.dtype == np.float32 and dist.shape == (2000,)
    assert np.abs(dist - exact).max() < 2e-3
    clear = np.abs(exact) > 2e-3
    assert np.array_equal(dist[clear] < 0, exact[clear] < 0)


def test_sign_on_vertices_and_edges(sphere):
    """Points straight out from (or in from) vertices and edge midpoints use vertex / edge pseudonormals."""
    verts, faces = sphere
    sdf = BodySDF(verts, faces)
    mids = 0.5 * (verts[faces[:, 0]] + verts[faces[:, 1]])
    for base in (verts, mids):
        out = sdf.query(base * 1.05)
        inside = sdf.query(base * 0.95)
        assert out.min() > 0 and inside.max() < 0


def test_matches_libigl_on_body(body):
    verts, faces = body.rest_verts().astype(np.float64), body.faces
    sdf = BodySDF(verts, faces)
    rng = np.random.default_rng(1)
    points = verts[rng.integers(0, len(verts), 3000)] + rng.normal(0, 0.03, (3000, 3))
    ref, _, ref_close, _ = igl.signed_distance(points, verts, faces, igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)
    dist, close, face = sdf.closest(points)
    np.testing.assert_allclose(dist, ref, atol=1e-6)
    np.testing.assert_allclose(close, ref_close, atol=1e-6)
    # The closest point lies on the returned face and at |dist| from the query.
    np.testing.assert_allclose(np.linalg.norm(points - close, axis=1), np.abs(dist), atol=1e-6)
    tri = verts[faces[face]]
    bary = igl.barycentric_coordinates(close.astype(np.float64), tri[:, 0].copy(), tri[:, 1].copy(), tri[:, 2].copy())
    # float32 closest points: barycentric coordinates exact to float32 rounding over ~1 cm faces
    assert bary.min() > -1e-3 and np.abs(bary.sum(1) - 1).max() < 1e-4


@pytest.mark.parametrize("backend", ["warp", "igl"])
def test_inside_by_winding_number_on_two_overlapping_spheres(sphere, backend):
    """Two unit spheres in one mesh, 1.2 apart along x (a body through itself): a point is inside where it is
    inside either sphere, in closed form; at x = 0.15, 5 cm from the second sphere whose side faces it, the
    pseudonormal sign says outside. Points more than 2 mm from both surfaces (the icosphere's deviation is under
    1.3 mm); the hierarchy of the first call is reused by the second, with the same answers."""
    verts, faces = sphere
    both = BodySDF(np.concatenate([verts, verts + [1.2, 0, 0]]), np.concatenate([faces, faces + len(verts)]))
    rng = np.random.default_rng(1)
    points = rng.uniform([-1.3, -1.2, -1.2], [2.5, 1.2, 1.2], (3000, 3))
    r = np.stack([np.linalg.norm(points, axis=1), np.linalg.norm(points - [1.2, 0, 0], axis=1)], 1)
    points = points[(np.abs(r - 1.0) > 2e-3).all(1)]
    r = r[(np.abs(r - 1.0) > 2e-3).all(1)]
    inside = (r < 1.0).any(1)
    got = both.inside(points, backend=backend)
    assert got.dtype == bool and np.array_equal(got, inside) and 0.3 < inside.mean() < 0.7
    assert np.array_equal(both.inside(points[::-1], backend=backend), inside[::-1])
    assert both.query([[0.15, 0.0, 0.0]])[0] > 0.04 and both.inside([[0.15, 0.0, 0.0]], backend=backend)[0]
    assert both.inside(np.zeros((0, 3)), backend=backend).shape == (0,)
    with pytest.raises(InputError, match="winding number backend"):
        both.inside(points, backend="cuda")


def test_bad_input():
    with pytest.raises(InputError, match="BodySDF needs"):
        BodySDF(np.zeros((4, 2)), np.zeros((1, 3), int))
