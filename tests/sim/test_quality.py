import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.geometry.normals import vertex_normals
from loosefit.geometry.signed_distance import BodySDF
from loosefit.sim.quality import PENETRATION_DEPTH, QualityGate, body_contact, edge_strain, measure


def test_edge_strain_closed_form():
    rest = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    frames = np.stack([rest, rest * 1.1, rest * [1.0, 0.5, 1.0]])
    # Frame 2 halves y: the vertical edges shrink by 0.5, the diagonal to sqrt(1.25)/sqrt(2).
    diagonal = 1 - np.sqrt(1.25) / np.sqrt(2)
    expected = [[0, 0, 0, 0, 0], [0.1] * 5, [0.0, 0.5, diagonal, 0.5, 0.0]]  # edges (0,1) (0,2) (1,2) (1,3) (2,3)
    np.testing.assert_allclose(edge_strain(frames, rest, faces), expected, atol=1e-6)


@pytest.fixture(scope="module")
def shell(proxy_body):
    """Points 5 mm inside, 5 mm outside and 5 cm outside the (low-resolution) body, two frames."""
    rng = np.random.default_rng(0)
    frames = np.stack([proxy_body.rest_verts(), proxy_body.pose(_bend(proxy_body)).verts[0]])
    normals = vertex_normals(frames, proxy_body.faces)
    pick = rng.choice(frames.shape[1], 300, replace=False)
    offsets = np.repeat([-0.005, 0.005, 0.05], 100)
    points = frames[:, pick] + offsets[None, :, None] * normals[:, pick]
    return frames, points, offsets


def _bend(body):
    motion = body.rest_motion(1)
    motion.rotations[0, body.joint_names.index("LeftUpLeg"), 0] = -1.0
    motion.rotations[0, body.joint_names.index("Spine"), 1] = 0.5
    return motion


def test_body_contact_matches_brute_force(proxy_body, shell):
    frames, points, offsets = shell
    pinned = offsets == 0.05
    inside, deepest, gaps = body_contact(points, pinned, frames, proxy_body.faces)
    assert gaps.shape == (2, pinned.sum())
    gap = gaps.max(1)
    for t in range(2):
        exact = BodySDF(frames[t], proxy_body.faces).query(points[t])
        assert inside[t] == pytest.approx((exact < -PENETRATION_DEPTH).mean())
        assert deepest[t] == pytest.approx(max(0.0, -exact.min()), abs=1e-6)
        assert 0.3 < inside[t] <= 1 / 3 + 1e-9  # (nearly) all of the 5 mm-deep third
        # The pinned gap is the distance to the nearest body vertex: an upper bound of the exact one.
        assert np.abs(exact[pinned]).max() - 1e-6 <= gap[t] <= np.abs(exact[pinned]).max() + 0.03


def test_measure_and_gate(proxy_body, shell):
    frames, points, offsets = shell
    clear = np.all([BodySDF(f, proxy_body.faces).query(p) > 0 for f, p in zip(frames, points)], axis=0)
    outside = points[:, clear]  # some offset points fall into another limb in the bent pose
    faces = np.array([[0, 1, 2]])
    pinned = np.zeros(outside.shape[1], bool)
    stats = measure(outside, outside[0], faces, pinned, frames, proxy_body.faces, frames[0], fps=30.0)
    assert stats["penetration"] == 0.0 and stats["pinned_distance"] == 0.0 and not stats["nan"]
    # Pinned vertices: their distance to the nearest body vertex, and its change from the rest pose.
    glued = outside.copy()
    glued[:, 0] = frames[:, 7] + [0.0, 0.0, 0.001]
    glued[1, 0, 2] += 0.005  # proxy vertices are about 3 cm apart: vertex 7 stays the nearest
    stats = measure(glued, glued[0], faces, np.arange(glued.shape[1]) == 0, frames, proxy_body.faces, frames[0], fps=30.0)
    assert stats["pinned_distance"] == pytest.approx(0.006, abs=1e-5)
    assert stats["pinned_drift"] == pytest.approx(0.005, abs=1e-5)
    assert QualityGate().check(stats) == ("ok", "")
    assert "pinned vertices moved 0.005 m" in QualityGate(max_pinned_drift=0.004).check(stats)[1]
    # Another part of the body coming up to a pin (a thigh raised to the waistband) is not drift: the
    # pin keeps its distance to its anchor, vertex 7, while the nearest body vertex is now much closer.
    approached = frames.copy()
    glued[1, 0] = approached[1, 7] + [0.0, 0.0, 0.001]
    approached[1, 8] = glued[1, 0] + [0.0, 0.0, 0.0003]
    pin = np.arange(glued.shape[1]) == 0
    assert body_contact(glued, pin, approached, proxy_body.faces)[2][:, 0] == pytest.approx([0.001, 0.0003], abs=1e-6)
    stats = measure(glued, glued[0], faces, pin, approached, proxy_body.faces, approached[0], fps=30.0)
    assert stats["pinned_drift"] == pytest.approx(0.0, abs=1e-6)
    fast = outside.copy()
    fast[1] += [2.0, 0.0, 0.0]  # 2 m in one frame: 60 m/s
    status, reason = QualityGate().check(measure(fast, fast[0], faces, pinned, frames, proxy_body.faces, frames[0], fps=30.0))
    assert status == "failed" and "exploded" in reason
    pinned = np.zeros(points.shape[1], bool)
    stats = measure(points, points[0], faces, pinned, frames, proxy_body.faces, frames[0], fps=30.0)
    status, reason = QualityGate().check(stats)
    assert status == "failed" and "penetration" in reason
    broken = points.copy()
    broken[1, 0] = np.nan
    stats = measure(broken, points[0], faces, pinned, frames, proxy_body.faces, frames[0], fps=30.0)
    assert QualityGate().check(stats) == ("failed", "NaN or infinite vertex positions")


def test_gate_limits_from_dict():
    assert QualityGate.from_dict({"max_strain": 1}).max_strain == 1.0
    with pytest.raises(InputError, match="unknown quality gate limits"):
        QualityGate.from_dict({"strain": 1})
    with pytest.raises(InputError, match="max_speed"):
        QualityGate.from_dict({"max_speed": -1})
