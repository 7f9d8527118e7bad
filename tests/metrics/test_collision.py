"""Collision ratio with a closed box as the body: static, per-frame and moving bodies, tolerance."""

import numpy as np
import pytest
import trimesh

from loosefit.errors import InputError
from loosefit.geometry.signed_distance import BodySDF
from loosefit.metrics.collision import collision_mask, collision_ratio, collision_ratio_per_frame, surface_samples

BOX = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
BV, BF = np.asarray(BOX.vertices), np.asarray(BOX.faces)
POINTS = np.array([[0.0, 0, 0], [0.4995, 0, 0], [2.0, 0, 0], [0, 0.3, 0.2]])  # deep, 0.5 mm deep, outside, deep


def test_ratio_counts_vertices_deeper_than_the_tolerance():
    assert collision_mask(POINTS, BodySDF(BV, BF)).tolist() == [[True, False, False, True]]
    assert collision_ratio(POINTS, BodySDF(BV, BF)) == pytest.approx(50.0)
    assert collision_ratio(POINTS, BV, BF, tolerance=0.0) == pytest.approx(75.0)


def test_moving_body_and_per_frame_sdfs():
    garment = np.stack([POINTS, POINTS])
    body = np.stack([BV, BV + [3.0, 0, 0]])  # the box slides away in frame 1
    assert collision_ratio_per_frame(garment, body, BF).tolist() == [50.0, 0.0]
    sdfs = [BodySDF(b, BF) for b in body]
    assert collision_ratio(garment, sdfs) == pytest.approx(25.0)


def test_surface_samples_see_a_box_edge_between_outside_vertices():
    """A square in the plane x + y = 0.9 across an edge of the box (half-width 0.5): its corners are 0.1 m outside
    (two beyond x = 0.5, two beyond y = 0.5), while the midpoints of the three edges along x = y lie 5 cm inside
    (0.45, 0.45, z) and the centroids exactly on the box's faces. Samples: the 5 edge midpoints, then the 2
    centroids, in closed form."""
    verts = np.array([[0.6, 0.3, -0.3], [0.3, 0.6, -0.3], [0.3, 0.6, 0.3], [0.6, 0.3, 0.3]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    samples = surface_samples(np.stack([verts, verts + [0, 0, 5.0]]), faces)  # frame 1: lifted off the box
    assert samples.shape == (2, 7, 3)
    edges = [(0, 1), (0, 2), (0, 3), (1, 2), (2, 3)]  # sorted unique pairs
    np.testing.assert_allclose(samples[0, :5], [(verts[i] + verts[j]) / 2 for i, j in edges])
    np.testing.assert_allclose(samples[0, 5:], [verts[f].mean(0) for f in faces])
    assert collision_ratio_per_frame(verts[None], BV, BF).tolist() == [0.0]
    inside = collision_mask(samples, np.stack([BV, BV]), BF)
    assert inside.tolist() == [[True, True, False, False, True, False, False], [False] * 7]


def test_bad_bodies():
    with pytest.raises(InputError, match="faces"):
        collision_ratio(POINTS, BV)
    with pytest.raises(InputError, match=r"\(3, Vb, 3\)"):
        collision_ratio(np.stack([POINTS] * 3), np.stack([BV, BV]), BF)
    with pytest.raises(InputError, match="tolerance"):
        collision_ratio(POINTS, BV, BF, tolerance=-1)


def test_posed_frames_share_the_edge_map_and_give_the_same_distances():
    """A deformed sphere over three frames (a non-rigid squash and a shear): each frame's PosedBodySDF, built
    with the first frame's edge map, gives BodySDF's distances, closest points and faces bit for bit, at
    points near the surface where the edge and vertex pseudonormals decide the sign."""
    from loosefit.metrics.collision import PosedBodySDF, posed_body_sdfs

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    v0, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    frames = np.stack([v0, v0 * [1.3, 1.0, 0.7], v0 + np.outer(v0[:, 2], [0.5, 0.0, 0.0])])
    rng = np.random.default_rng(0)
    for verts, sdf in zip(frames, posed_body_sdfs(frames, faces)):
        full = BodySDF(verts, faces)
        # points just inside and outside the surface, over vertices, edge midpoints and face centres
        edges = verts[faces[:, [0, 1]]].mean(1)
        anchors = np.concatenate([verts, edges, verts[faces].mean(1)])
        points = anchors * (1 + rng.uniform(-0.05, 0.05, (len(anchors), 1)))
        for a, b in zip(sdf.closest(points), full.closest(points)):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(sdf._edge_normals, full._edge_normals)
        assert ((sdf.query(points) < 0) == (np.linalg.norm(points, axis=1) < np.linalg.norm(anchors, axis=1))).mean() > 0.95
    with pytest.raises(InputError, match="like its first frame"):
        PosedBodySDF(v0[:-1], BodySDF(v0, faces))
    # the ratio over a posed sequence (the generator path) is the one from a BodySDF a frame
    garment = frames[:, ::3] * 0.98
    assert collision_ratio_per_frame(garment, frames, faces).tolist() == pytest.approx(
        collision_ratio_per_frame(garment, [BodySDF(v, faces) for v in frames]).tolist())
