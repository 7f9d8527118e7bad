"""FitGar's per-frame inputs (models/fitgar_inputs.py) against the whole posed body."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.geometry.features import relative_skinning_features
from loosefit.geometry.normals import vertex_normals
from loosefit.models.fitgar_inputs import GarmentBodyPair, graph_edges, pose_vector
from loosefit.models.motion_features import to_canonical


@pytest.fixture(scope="module")
def case(body):
    from loosefit.garment import make_garment
    from loosefit.motion.procedural import generate

    garment = make_garment("skirt", body, seed=0, edge_length=0.06)
    motion = generate("spin", 1.0, 2, body)
    pair = GarmentBodyPair.build(garment.verts, garment.faces, body, body.shape.to_array(), [0.1, 0.2, 0.3])
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
