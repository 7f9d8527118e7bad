import numpy as np

from loosefit.motion.motion import Motion
from loosefit.sim.attach import body_lbs, garment_weights, skin_garment


def _motion(body, frames=3):
    rng = np.random.default_rng(3)
    rot = rng.normal(scale=0.3, size=(frames, body.num_joints, 3)).astype(np.float32)
    trans = np.tile(np.array([1.0, 2.0, 0.9], np.float32), (frames, 1))
    return Motion(rot, trans, 30.0, body.rig, body.joint_names, "test")


def test_skinning_follows_the_body(proxy_body):
    body = proxy_body
    motion = _motion(body, frames=3)
    picks = np.array([10, 500, 900])
    verts = body.rest_verts()[picks]
    weights = garment_weights(verts, body)
    np.testing.assert_allclose(weights.sum(1), 1.0, atol=1e-5)
    np.testing.assert_allclose(weights, body.skinning_weights()[picks])
    expected = body.pose(motion).verts[:, picks]
    np.testing.assert_allclose(skin_garment(verts, weights, body, motion), expected, atol=1e-5)
    np.testing.assert_allclose(body_lbs(verts, body, motion), expected, atol=1e-5)  # the baseline in one call
    still = skin_garment(verts, weights, body, body.rest_motion(2))
    np.testing.assert_allclose(still, np.broadcast_to(verts, still.shape), atol=1e-6)
