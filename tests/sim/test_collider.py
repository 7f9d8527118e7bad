import igl
import numpy as np

from loosefit.sim.collider import MAX_STEPS, collider_frames, enclosing_frames, inflated_rest, steps_per_frame


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


def test_enclosing_frames_keep_the_posed_full_body_inside(body, proxy_body):
    """Posed, the full body sticks out of the proxy (19 % of its vertices by more than 2 mm on a walk, measured);
    the proxy pushed frame by frame holds it inside but for fingertips and the faces' curvature (0.7 % by more
    than 2 mm, measured), and is only ever moved outwards, along its normals."""
    from loosefit.geometry.normals import vertex_normals
    from loosefit.motion.procedural import generate

    motion = generate("walk", 0.5, 3, body)
    full, plain = body.pose(motion).verts, proxy_body.pose(motion).verts
    enclosing = enclosing_frames(body, motion)
    assert enclosing.shape == plain.shape and enclosing.dtype == np.float32
    before = np.concatenate([_outside(full[t], plain[t], proxy_body.faces) for t in range(len(full))])
    after = np.concatenate([_outside(full[t], enclosing[t], proxy_body.faces) for t in range(len(full))])
    assert (before > 0.002).mean() > 0.1 and np.quantile(before, 0.99) > 0.008
    assert (after > 0.002).mean() < 0.01 and np.quantile(after, 0.99) < 0.0025
    for t in (0, len(full) - 1):
        move = enclosing[t] - plain[t]
        normal = vertex_normals(plain[t], proxy_body.faces)
        push = np.einsum("vd,vd->v", move, normal)
        assert push.min() > -1e-6 and push.max() > 0.005
        np.testing.assert_allclose(move, push[:, None] * normal, atol=1e-5)
    # Limited to a box (a skirt's, about the hips): the proxy far from it keeps the rest pose's push.
    hips = full[:, :, 2].max() * np.array([0.45, 0.6])
    box = full[:, (full[0, :, 2] > hips[0]) & (full[0, :, 2] < hips[1])]
    boxed = enclosing_frames(body, motion, within=box)
    low = np.nonzero(plain[0, :, 2] < 0.15)[0]  # feet and shins: nearest full vertices all outside the box
    rest = inflated_rest(body, proxy_body)
    np.testing.assert_allclose(np.linalg.norm(boxed[0, low] - plain[0, low], axis=1),
                               np.linalg.norm(rest[low] - proxy_body.rest_verts()[low], axis=1), atol=1e-4)


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
