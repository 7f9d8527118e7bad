"""MotionMeshSDF (Warp, several frames at once) against BodySDF (libigl), the reference."""

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.geometry import warp_sdf
from loosefit.geometry.signed_distance import BodySDF, posed_body_sdfs
from loosefit.motion.procedural import generate

pytestmark = pytest.mark.skipif(not warp_sdf.available(), reason="needs warp")


@pytest.fixture(scope="module")
def posed(proxy_body, body):
    """Three frames of the collision proxy on a walk, float64, and its faces."""
    motion = generate("walk", 1.0, 3, body)
    return proxy_body.pose(motion).verts[::10][:3].astype(np.float64), np.asarray(proxy_body.faces)


def test_signed_distances_equal_libigl_around_a_posed_body(posed):
    verts, faces = posed
    field = warp_sdf.MotionMeshSDF(faces, capacity=4).refit(verts)
    rng = np.random.default_rng(0)
    for t, ref in enumerate(posed_body_sdfs(verts, faces)):
        points = verts[t][rng.integers(0, len(verts[t]), 3000)] + rng.normal(0, 0.03, (3000, 3))
        # on the surface too: at vertices, edge midpoints and just off them
        points = np.concatenate([points, verts[t][:200], 0.5 * (verts[t][faces[:200, 0]] + verts[t][faces[:200, 1]])])
        dist, close, face = field.query(points, np.full(len(points), t))
        ref_dist, ref_close, _ = ref.closest(points)
        np.testing.assert_allclose(dist, ref_dist, atol=1e-5)
        # the closest point itself can differ where two triangles are equally near (to float32 rounding)
        assert (np.linalg.norm(close - ref_close, axis=1) > 1e-5).mean() < 5e-3
        np.testing.assert_allclose(np.linalg.norm(points - close, axis=1), np.abs(dist), atol=1e-9)
        # the winding number where the pseudonormal puts a point more than 5 mm out: libigl's winding number
        far = dist > 0.005
        wound, _, _ = field.query(points, np.full(len(points), t), winding_from=0.005)
        inside = BodySDF(verts[t], faces).inside(points[far], backend="igl")
        np.testing.assert_array_equal(wound[far] < 0, inside)
        np.testing.assert_array_equal(wound[~far], dist[~far])


def test_frames_are_queried_together_and_refitted(posed):
    verts, faces = posed
    field = warp_sdf.MotionMeshSDF(faces, capacity=3).refit(verts[:2])
    rng = np.random.default_rng(1)
    points = verts[0][rng.integers(0, len(verts[0]), 500)] + rng.normal(0, 0.02, (500, 3))
    frame = rng.integers(0, 2, 500)
    dist = field.query(points, frame)[0]
    for t in range(2):
        np.testing.assert_allclose(dist[frame == t], BodySDF(verts[t], faces).query(points[frame == t]), atol=1e-5)
    field.refit(verts[2:][::-1])  # fewer frames, other poses: the meshes refitted
    np.testing.assert_allclose(field.query(points, np.zeros(500))[0], BodySDF(verts[2], faces).query(points),
                               atol=1e-5)
    with pytest.raises(InputError):
        field.query(points, np.ones(500))  # one frame held now
    with pytest.raises(InputError):
        field.refit(np.concatenate([verts, verts]))  # over capacity


def _box_mesh(low, n: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """A unit cube at ``low``, each face a grid of ``n x n`` squares cut in two triangles, normals outwards."""
    import trimesh

    box = trimesh.creation.box(extents=(1, 1, 1))
    for _ in range(n // 2):
        box = box.subdivide()
    return np.asarray(box.vertices) + 0.5 + np.asarray(low, float), np.asarray(box.faces)


def test_the_winding_number_counts_rays_through_edges_and_vertices_once_and_overlaps_twice():
    """Two cubes overlapping as one mesh that passes through itself (winding number 2 where both hold a point),
    asked at a lattice of points whose axis rays run exactly along the cubes' edges and through their vertices:
    every point inside either cube is inside, every other point outside (closed form)."""
    va, fa = _box_mesh((0, 0, 0))
    vb, fb = _box_mesh((0.5, 0.5, 0.25))
    verts = np.concatenate([va, vb])[None]
    faces = np.concatenate([fa, fb + len(va)])
    field = warp_sdf.MotionMeshSDF(faces, capacity=1).refit(verts)
    ticks = np.arange(-0.25, 1.8, 0.125)  # the cubes' vertices lie on multiples of 0.25
    points = np.stack(np.meshgrid(ticks, ticks, ticks, indexing="ij"), -1).reshape(-1, 3)
    inside = ((points > 0) & (points < 1)).all(1) | ((points > vb.min(0)) & (points < vb.max(0))).all(1)
    dist = field.query(points, np.zeros(len(points)), winding_from=0.0)[0]
    off = dist != 0  # not on either surface
    both = ((points > 0) & (points < 1)).all(1) & ((points > vb.min(0)) & (points < vb.max(0))).all(1)
    assert inside[off].sum() > 500 and both[off].sum() > 40 and (~inside[off]).sum() > 1000
    np.testing.assert_array_equal(dist[off] < 0, inside[off])
