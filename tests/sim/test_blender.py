import numpy as np
import pytest

from loosefit.sim.blender import cloth_settings, run_cloth, scene_gravity
from loosefit.sim.params import SimParams


def test_cloth_settings_closed_form():
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    p = SimParams(density=0.2, tension=1000.0, compression=500.0, shear=50.0, bending=1e-5,
                  stretch_damping=100.0, bending_damping=4.0, air_drag=0.1, quality=7, time_scale=0.5)
    s = cloth_settings(p, verts, faces, fps=30.0)
    edge = (4 + np.sqrt(2)) / 5  # four sides and one diagonal
    mass = 0.2 * 1.0 / 4
    expected = {
        "mass": mass,
        "tension_stiffness": 1000 * edge / 900,
        "compression_stiffness": 500 * edge / 900,
        "shear_stiffness": 50 * edge / 900,
        "bending_stiffness": 10 * 1e-5 / edge**2 / 900,
        "tension_damping": 100 * mass / 30,
        "compression_damping": 100 * mass / 30,
        "shear_damping": 100 * mass / 30,
        "bending_damping": 4 * mass / 30,
        "air_damping": 100 * 0.1 * 0.25 / 30,
        "quality": 7,
        "time_scale": 0.5,
    }
    assert s == pytest.approx(expected, rel=1e-6)
    assert scene_gravity(p, 30.0) == pytest.approx(1000 * 9.81 / 900)


def _patch(n=6, size=0.3, z=5.0):
    x, y = np.meshgrid(np.linspace(0, size, n), np.linspace(0, size, n))
    verts = np.stack([x.ravel(), y.ravel(), np.full(n * n, z)], 1).astype(np.float32)
    faces = [(i * n + j, i * n + j + 1, (i + 1) * n + j + 1) for i in range(n - 1) for j in range(n - 1)]
    faces += [(i * n + j, (i + 1) * n + j + 1, (i + 1) * n + j) for i in range(n - 1) for j in range(n - 1)]
    return verts, np.array(faces, np.int64)


def test_free_fall_follows_gravity_and_time_scale():
    verts, faces = _patch()
    frames = 31  # one second after the start frame
    garment = np.repeat(verts[None], frames, 0)
    collider = np.repeat(np.array([[[50.0, 0, 0], [51, 0, 0], [50, 1, 0]]], np.float32), frames, 0)
    pinned = np.zeros(len(verts), bool)
    drops = []
    for time_scale in (1.0, 0.5):
        params = SimParams(air_drag=0.0, time_scale=time_scale)
        out, seconds = run_cloth(faces, pinned, garment, collider, np.array([[0, 1, 2]]), params, 30.0)
        assert out.shape == garment.shape and seconds.shape == (frames,)
        np.testing.assert_allclose(out[0], verts)
        drops.append(verts[:, 2].mean() - out[-1, :, 2].mean())
    assert drops[0] == pytest.approx(0.5 * 9.81, rel=0.05)  # free fall for 1 s
    assert drops[1] == pytest.approx(drops[0] / 4, rel=0.05)  # half the time: a quarter of the fall


def test_pinned_vertices_follow_their_targets():
    verts, faces = _patch(z=1.0)
    frames = 10
    path = np.linspace(0, 0.5, frames)[:, None, None] * np.array([1.0, 0.0, 0.2])  # pins slide along +X, up
    garment = (verts[None] + path).astype(np.float32)
    pinned = np.zeros(len(verts), bool)
    pinned[:6] = True  # the first row
    collider = np.repeat(np.array([[[50.0, 0, 0], [51, 0, 0], [50, 1, 0]]], np.float32), frames, 0)
    out, _ = run_cloth(faces, pinned, garment, collider, np.array([[0, 1, 2]]), SimParams(), 30.0)
    np.testing.assert_allclose(out[:, pinned], garment[:, pinned], atol=1e-5)
    assert np.abs(out[-1, ~pinned, 2] - garment[-1, ~pinned, 2]).max() > 0.01  # the rest hangs


def test_the_floor_stops_falling_cloth():
    """A patch dropped from 0.3 m lands on a floor at z = 0.1 and rests there, within the collision distance;
    without the floor it falls through (0.5 g t^2 = 1.2 m in 0.5 s)."""
    verts, faces = _patch(z=0.3)
    frames = 16
    garment = np.repeat(verts[None], frames, 0)
    collider = np.repeat(np.array([[[50.0, 0, 0], [51, 0, 0], [50, 1, 0]]], np.float32), frames, 0)
    pinned = np.zeros(len(verts), bool)
    params = SimParams(air_drag=0.0, quality=10)
    landed, _ = run_cloth(faces, pinned, garment, collider, np.array([[0, 1, 2]]), params, 30.0, floor=0.1)
    fallen, _ = run_cloth(faces, pinned, garment, collider, np.array([[0, 1, 2]]), params, 30.0)
    assert landed[-1, :, 2].min() > 0.1 - 0.002 and landed[-1, :, 2].max() < 0.1 + 2 * params.collision_distance
    assert fallen[-1, :, 2].max() < 0.0
