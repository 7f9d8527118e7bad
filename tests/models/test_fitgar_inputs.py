"""FitGar's per-frame inputs (models/fitgar_inputs.py) against the whole posed body, for both anchors: the closest
body vertex and the closest point on the body surface."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from loosefit.errors import InputError
from loosefit.geometry.features import closest_body_points, relative_skinning_features
from loosefit.geometry.normals import vertex_normals
from loosefit.models.fitgar_inputs import GarmentBodyPair, graph_edges, pose_vector, shared_anchor_fraction
from loosefit.motion.heading import to_canonical


@pytest.fixture(scope="module")
def case(body):
    from loosefit.garment import make_garment
    from loosefit.motion.procedural import generate

    garment = make_garment("skirt", body, seed=0, edge_length=0.06)
    motion = generate("spin", 1.0, 2, body)
    pair = GarmentBodyPair.build(garment.verts, garment.faces, body, body.shape.to_array(), [0.1, 0.2, 0.3],
                                 anchor="vertex")
    return body, garment, motion, pair, pair.frames(motion), body.pose(motion)


def test_indicator_and_anchor_follow_the_whole_body(case):
    body, garment, motion, pair, inputs, posed = case
    rest = body.rest_verts()
    d = np.linalg.norm(garment.verts[:, None] - rest[None], axis=-1)
    assert np.array_equal(pair.nearest, d.argmin(1))
    expected = to_canonical(posed.verts[:, pair.nearest], inputs["rot"], inputs["origin"])
    np.testing.assert_allclose(inputs["anchor"], expected, atol=1e-5)
    np.testing.assert_allclose(inputs["joints"], to_canonical(posed.joints, inputs["rot"], inputs["origin"]), atol=1e-5)


def test_relative_skinning_features_match_geometry_features(case):
    """geometry.features' world features, turned into the heading frame about the rest root."""
    body, garment, motion, pair, inputs, posed = case
    root = body.rest_joints()[0]
    centre = np.array([root[0], root[1], 0.0])
    for key, rest in (("body_rel", body.rest_verts()[pair.nearest]), ("garment_rel", garment.verts)):
        world = relative_skinning_features(rest, body.skinning_weights()[pair.nearest], posed.joint_transforms,
                                           body.rest_joints())
        np.testing.assert_allclose(inputs[key], (world - centre) @ inputs["rot"], atol=1e-5)
    # the root's translation does not enter: a walk moves the anchor but not the feature's horizontal centre
    assert np.ptp(inputs["body_rel"][:, :, 2].mean(1)) < np.ptp(posed.verts[:, pair.nearest, 2].mean(1)) + 1e-6


def test_normals_are_those_of_the_whole_posed_body(case):
    """Only the one-ring of the indicated vertices is skinned, and that gives their exact normals."""
    body, garment, motion, pair, inputs, posed = case
    exact = vertex_normals(posed.verts, body.faces)[:, pair.nearest] @ inputs["rot"]
    np.testing.assert_allclose(inputs["body_normal"], exact, atol=1e-4)
    assert len(pair.ring_rest) < 0.5 * body.num_verts


def test_pose_and_edges(case):
    body, garment, motion, pair, inputs, posed = case
    J = body.num_joints
    assert inputs["pose"].shape == (motion.num_frames, 6 * J)
    rest = pose_vector(body.rest_motion(2))
    np.testing.assert_allclose(rest, np.tile([1, 0, 0, 0, 1, 0], (2, J)), atol=1e-6)  # identity rotations
    e = graph_edges(np.array([[0, 1, 2]]))
    assert sorted(map(tuple, e.T.tolist())) == [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)]


def test_bad_input(case):
    body, garment, motion, pair, inputs, posed = case
    with pytest.raises(InputError):
        GarmentBodyPair.build(garment.verts, garment.faces, body, body.shape.to_array(), [np.nan])
    with pytest.raises(InputError, match="anchor must be one of"):
        GarmentBodyPair.build(garment.verts, garment.faces, body, body.shape.to_array(), [0.1], anchor="nearest")


@pytest.fixture(scope="module")
def surface(case):
    body, garment, motion, _, _, posed = case
    pair = GarmentBodyPair.build(garment.verts, garment.faces, body, body.shape.to_array(), [0.1, 0.2, 0.3],
                                 anchor="surface")
    return pair, pair.frames(motion)


def test_surface_anchor_is_the_closest_point_of_the_body(case, surface):
    """Against brute force: a fine barycentric grid on every body triangle near a few garment vertices."""
    body, garment, *_ = case
    pair, _ = surface
    assert pair.anchor == "surface"
    rest, faces = body.rest_verts().astype(np.float64), np.asarray(body.faces)
    anchors = pair.rest_anchors()
    dist = np.linalg.norm(garment.verts - anchors, axis=1)
    to_vertex = np.linalg.norm(garment.verts[:, None] - rest[None], axis=-1).min(1)
    assert (dist <= to_vertex + 1e-7).all() and (dist < to_vertex - 1e-4).mean() > 0.5
    n = 40
    u, v = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
    keep = u + v <= n
    grid = np.stack([u[keep], v[keep], n - u[keep] - v[keep]], 1) / n  # (P, 3) barycentric
    for i in np.linspace(0, len(anchors) - 1, 6).round().astype(int):
        near = np.linalg.norm(rest - garment.verts[i], axis=1) < to_vertex[i] + 0.03
        tri = rest[faces[near[faces].any(1)]]  # (K, 3, 3)
        samples = np.einsum("pk,fkc->fpc", grid, tri).reshape(-1, 3)
        brute = np.linalg.norm(samples - garment.verts[i], axis=1).min()
        assert dist[i] <= brute + 1e-7 and dist[i] > brute - 2e-3, (i, dist[i], brute)


def test_surface_anchor_follows_the_posed_surface(case, surface):
    """The anchor, its normal and skinning weights interpolated on the posed body's triangle."""
    body, garment, motion, _, _, posed = case
    pair, inputs = surface
    face, bary = closest_body_points(garment.verts, body.rest_verts(), body.faces)
    np.testing.assert_allclose(pair.bary, bary, atol=1e-12)
    corners = np.asarray(body.faces)[face]
    expected = np.einsum("vk,tvkc->tvc", bary, posed.verts[:, corners])
    np.testing.assert_allclose(inputs["anchor"], to_canonical(expected, inputs["rot"], inputs["origin"]), atol=1e-5)
    normal = np.einsum("vk,tvkc->tvc", bary, vertex_normals(posed.verts, body.faces)[:, corners])
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    np.testing.assert_allclose(inputs["body_normal"], normal @ inputs["rot"], atol=1e-4)
    weights = np.einsum("vk,vkj->vj", bary, body.skinning_weights()[corners])
    np.testing.assert_allclose(pair.weights, weights, atol=1e-6)
    root = body.rest_joints()[0]
    world = relative_skinning_features(garment.verts, weights, posed.joint_transforms, body.rest_joints())
    np.testing.assert_allclose(inputs["garment_rel"], (world - [root[0], root[1], 0.0]) @ inputs["rot"], atol=1e-5)


def test_shared_anchor_fraction(case, surface):
    """Closest-vertex anchors: the share of vertices whose body vertex another one also has (counted directly);
    surface anchors share far fewer."""
    pair = case[3]
    count = np.bincount(pair.nearest)
    shared = shared_anchor_fraction(pair)
    assert shared["fraction"] == pytest.approx((count[pair.nearest] > 1).mean())
    assert shared["largest"] == count.max() and shared["vertices"] == pair.num_verts
    on_surface = shared_anchor_fraction(surface[0])
    assert on_surface["fraction"] < 0.5 * shared["fraction"], (on_surface, shared)


def test_normal_anchor_is_where_the_body_normal_points_at_the_vertex(case, surface):
    """The projection along the normals: each garment vertex lies on the body's interpolated normal from its anchor
    (t > 0; the corners' normals from the faces around them, as the inputs take them), at least as far as its closest
    point; anchors are shared no more than the closest points are."""
    body, garment, *_ = case
    pair = GarmentBodyPair.build(garment.verts, garment.faces, body, body.shape.to_array(), [0.1, 0.2, 0.3],
                                 anchor="normal")
    anchors = pair.rest_anchors()
    corner_normals = vertex_normals(pair.ring_rest, pair.ring_faces).astype(np.float64)[pair.ring_tri]
    normal = np.einsum("vk,vkc->vc", pair.bary, corner_normals)
    t = np.einsum("vc,vc->v", garment.verts - anchors, normal) / np.einsum("vc,vc->v", normal, normal)
    assert (t > 0).all()
    np.testing.assert_allclose(anchors + t[:, None] * normal, garment.verts, atol=1e-5)
    closest = np.linalg.norm(garment.verts - surface[0].rest_anchors(), axis=1)
    assert (np.linalg.norm(garment.verts - anchors, axis=1) >= closest - 1e-7).all()
    assert shared_anchor_fraction(pair)["fraction"] <= shared_anchor_fraction(surface[0])["fraction"]


def test_spread_anchor_is_the_normal_projection_with_shared_anchors_moved_apart(body):
    """The default anchor, on a long dress whose hem's projections meet at the toes: the projection along the
    normals wherever no other vertex's is within 1 mm; no two anchors within 1 mm; a moved anchor stays within a
    centimetre of its projection."""
    from loosefit.garment import make_garment

    garment = make_garment("dress", body, seed=0, edge_length=0.05)
    args = (garment.verts, garment.faces, body, body.shape.to_array(), [0.1, 0.2, 0.3])
    spread, normal = GarmentBodyPair.build(*args), GarmentBodyPair.build(*args, anchor="normal")
    assert spread.anchor == "spread"
    assert shared_anchor_fraction(spread)["fraction"] == 0.0
    projected = normal.rest_anchors()
    close = cKDTree(projected).query_pairs(1e-3, output_type="ndarray")
    alone = np.setdiff1d(np.arange(normal.num_verts), close.ravel())
    np.testing.assert_allclose(spread.rest_anchors()[alone], projected[alone], atol=1e-12)
    assert len(close), "the case should share some projections"
    assert np.linalg.norm(spread.rest_anchors() - projected, axis=1).max() < 0.01
