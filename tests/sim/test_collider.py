import igl
import numpy as np

from loosefit.sim.collider import MAX_STEPS, collider_frames, inflated_rest, steps_per_frame


def _outside(points, verts, faces):
    return igl.signed_distance(points.astype(np.float64), verts.astype(np.float64), faces,
                               igl.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER)[0]


def test_inflated_proxy_encloses_the_full_body(body, proxy_body):
    full = body.rest_verts()
    before = _outside(full, proxy_body.rest_verts(), proxy_body.faces)
    inflated = inflated_rest(body, proxy_body)
    after = _outside(full, inflated, proxy_body.faces)
    assert before.max() > 0.02 and np.quantile(before, 0.99) > 0.01  # the plain proxy lies inside the body
    assert after.max() < 0.006 and np.quantile(after, 0.99) < 0.002
    assert np.quantile(_outside(inflated, full, body.faces), 0.99) < 0.01  # and hugs it
    motion = body.rest_motion(2)
    motion.rotations[1, body.joint_names.index("LeftUpLeg"), 0] = -0.8
    verts, faces = collider_frames(body, motion)
    assert verts.shape == (2, len(inflated), 3) and np.array_equal(faces, proxy_body.faces)
    np.testing.assert_allclose(verts[0], inflated, atol=1e-5)
    assert np.abs(verts[1] - inflated).max() > 0.1  # posed by the proxy's skinning
    full_verts, full_faces = collider_frames(body, motion, kind="full")
    assert full_verts.shape == (2, body.num_verts, 3) and np.array_equal(full_faces, body.faces)


def test_steps_per_frame():
    garment = np.zeros((1, 3))
    near = np.array([[0.05, 0.0, 0.0], [5.0, 0.0, 0.0]])  # one collider vertex 5 cm away, one 5 m away
    moves = np.array([[0.05, 0.0, 0.0], [3.0, 0.0, 0.0]])  # per frame: 5 cm near, 3 m far
    collider = near[None] + np.arange(4)[:, None, None] * moves[None]
    assert steps_per_frame(collider, garment, 0.004, minimum=2) == 7  # ceil(0.05 / 0.008): the far vertex does not count
    assert steps_per_frame(collider, garment, 0.004, minimum=10) == 10
    assert steps_per_frame(collider * 100, garment, 0.004, minimum=2) == 2  # nothing near
    fast = near[None] + np.arange(4)[:, None, None] * np.array([[1.0, 0, 0], [0, 0, 0]])[None]
    assert steps_per_frame(fast, garment, 0.004, minimum=2) == MAX_STEPS
