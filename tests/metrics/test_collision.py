"""Collision ratio with a closed box as the body: static, per-frame and moving bodies, tolerance; penetration on
the surface (edge midpoints and centroids) of a sheet through a sphere and of a triangle across a box."""

import numpy as np
import pytest
import trimesh

from loosefit.errors import InputError
from loosefit.geometry.signed_distance import BodySDF
from loosefit.metrics.collision import (
    collision_mask,
    collision_ratio,
    collision_ratio_per_frame,
    inside_body_report,
    penetration,
    penetrations,
    surface_samples,
)
from tests.metrics.conftest import TRIANGLE, box_depth, sheet

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


def test_a_sheet_through_a_sphere():
    """A square sheet 0.1 m above the centre of a sphere of radius r = 0.3 m: the points deeper than d = 5 mm are
    those within r - d of the centre, a disk of radius sqrt((r - d)^2 - 0.1^2) on the sheet. Counted from the
    sample points themselves, between the sphere's inscribed (faces) and circumscribed (vertices) radius, where
    the tessellated body lies; as a share of the samples about the disk's share of the sheet's area. The
    deepest point is the sheet's centre, r - 0.1 deep."""
    r, h, d = 0.3, 0.1, 0.005
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=r)
    inradius = np.abs(np.einsum("ij,ij->i", sphere.face_normals, sphere.triangles[:, 0])).min()
    verts, faces = sheet(0.4, 40, h)
    found = penetration(verts, faces, BodySDF(np.asarray(sphere.vertices), np.asarray(sphere.faces)), depth=d)
    samples = surface_samples(verts, faces)
    assert found.samples == len(samples) and found.surface_percent.shape == (1,)
    centre = np.linalg.norm(samples, axis=1)
    surely, maybe = (100.0 * (centre < radius - d).mean() for radius in (inradius, r))
    assert surely <= found.surface_percent[0] <= maybe and maybe - surely < 0.5
    disk = np.pi * ((r - d) ** 2 - h**2) / 0.8**2
    assert found.surface_percent[0] == pytest.approx(100.0 * disk, abs=1.0)  # 37.8 %
    vert_centre = np.linalg.norm(verts, axis=1)
    assert (100.0 * (vert_centre < inradius - 1e-3).mean() <= found.vertex_percent[0]
            <= 100.0 * (vert_centre < r - 1e-3).mean())
    assert inradius - h <= found.deepest_m[0] <= r - h + 1e-6
    # the samples the depth bound skips change nothing: as if every sample were queried, also on a crumpled sheet
    body = BodySDF(np.asarray(sphere.vertices), np.asarray(sphere.faces))
    crumpled = verts + np.random.default_rng(0).normal(0, [0.01, 0.01, 0.05], verts.shape)
    frames = np.stack([verts, crumpled])
    found = penetration(frames, faces, body, depth=d)
    for t, frame in enumerate(frames):
        at_samples, at_vertices = -body.query(surface_samples(frame, faces)), -body.query(frame)
        assert found.surface_percent[t] == pytest.approx(100.0 * (at_samples > d).mean(), rel=1e-12)
        assert found.deepest_m[t] == max(at_samples.max(), at_vertices.max())


def test_a_triangle_across_a_box_between_its_vertices():
    """Vertex ratio 0; the surface ratio is the share of the 4 samples deeper than 5 mm, counted by the box's depth
    formula at each; the deepest point is the centroid, 0.3 m deep."""
    faces = np.array([[0, 1, 2]])
    samples = surface_samples(TRIANGLE, faces)
    assert (box_depth(TRIANGLE) < 0).all() and samples.shape == (4, 3)
    expected = 100.0 * (box_depth(samples) > 0.005).mean()
    assert expected == 75.0
    found = penetration(np.stack([TRIANGLE, TRIANGLE + [0, 0, 3.0]]), faces, BodySDF(BV, BF))  # then lifted off
    assert found.vertex_percent.tolist() == [0.0, 0.0]
    assert found.surface_percent == pytest.approx([expected, 0.0])
    assert found.deepest_m == pytest.approx([0.3, 0.0], abs=1e-6)
    # together with another garment on the same body: each as measured alone
    other = np.stack([POINTS[:3], POINTS[:3]])
    both = penetrations([(np.stack([TRIANGLE] * 2), faces), (other, faces)], np.stack([BV, BV]), BF)
    alone = penetration(other, faces, np.stack([BV, BV]), BF)
    assert both[1].vertex_percent.tolist() == alone.vertex_percent.tolist()
    assert alone.vertex_percent == pytest.approx([100 / 3] * 2)  # deep, 0.5 mm deep, outside
    assert both[1].deepest_m.tolist() == alone.deepest_m.tolist() and both[0].surface_percent.tolist() == [75.0] * 2
    with pytest.raises(InputError, match="frames on one body"):
        penetrations([(np.stack([TRIANGLE] * 2), faces), (TRIANGLE[None], faces)], BodySDF(BV, BF))


def test_inside_body_report_measures_the_surface_too():
    """``loosefit animate``'s line on a stand-in body (the box, moving away after frame 2 of 6) and the triangle:
    no vertex inside, 75 % of the samples in the frames with the box, the centroid 300 mm deep."""
    from types import SimpleNamespace

    from loosefit.motion import Motion

    shift = np.array([0, 0, 0, 5, 5, 5], np.float32)
    motion = Motion(np.zeros((6, 2, 3)), np.stack([shift, 0 * shift, 0 * shift], 1))
    body = SimpleNamespace(faces=BF, pose=lambda m: SimpleNamespace(verts=BV[None] + m.translation[:, None]))
    garment = np.repeat(TRIANGLE[None], 6, 0)
    report = inside_body_report(garment, body, motion, max_frames=4, faces=np.array([[0, 1, 2]]))
    assert report["frames"] == 4 and report["of_frames"] == 6  # frames 0, 2, 3, 5
    assert report["mean_percent"] == 0.0 and report["worst_percent"] == 0.0
    assert report["surface_mean_percent"] == pytest.approx(37.5) and report["surface_worst_percent"] == 75.0
    assert report["deepest_mm"] == pytest.approx(300.0, abs=1e-3)
    plain = inside_body_report(garment, body, motion, max_frames=4)  # without triangles: the vertices only
    assert plain["surface_mean_percent"] is None and plain["deepest_mm"] == 0.0
