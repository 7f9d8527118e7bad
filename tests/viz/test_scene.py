"""Mesh tracks, panels and cameras: projection, framing and following against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.viz.scene import (
    Camera,
    MeshTrack,
    check_panels,
    fit_camera,
    follow_offsets,
    frame_cameras,
    travels,
)
from tests.viz.conftest import triangle


def test_project_closed_form(front_camera):
    W, H = 200, 100
    tan_half = np.tan(np.radians(front_camera.view_angle) / 2)
    # The focal point is the image centre; a point at the top of the field of view is row 0; the
    # right edge is tan_half * W / H to the right (the vertical angle is fixed, the horizontal follows).
    points = np.array([[0, 0, 0], [0, 0, 5 * tan_half], [5 * tan_half * W / H, 0, 0], [0, 3, 0]], float)
    pixels, depth = front_camera.project(points, (W, H))
    np.testing.assert_allclose(pixels, [[100, 50], [100, 0], [200, 50], [100, 50]], atol=1e-9)
    np.testing.assert_allclose(depth, [5, 5, 5, 8])


def test_camera_basis_is_orthonormal_and_translation_moves_both_points(front_camera):
    basis = front_camera.basis()
    np.testing.assert_allclose(basis @ basis.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(basis, [[1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-12)
    moved = front_camera.translated([1, 2, 3])
    assert moved.position == (1, -3, 3) and moved.focal_point == (1, 2, 3)
    with pytest.raises(InputError, match="parallel"):
        Camera((0, 0, 5), (0, 0, 0)).basis()


def test_fit_camera_frames_every_vertex_tightly():
    rng = np.random.default_rng(0)
    verts = rng.uniform([-0.3, -0.2, 0.0], [0.3, 0.2, 1.7], (4, 500, 3)).astype(np.float32)
    track = MeshTrack(verts, np.array([[0, 1, 2]]))
    size, margin = (160, 120), 1.1
    camera = fit_camera([[track]], size, range(4), margin=margin)
    pixels, depth = camera.project(verts.reshape(-1, 3), size)
    assert (depth > 0).all()
    ndc = np.abs(pixels / np.array(size) * 2 - 1)
    # Every vertex in view, and the extreme one exactly at 1 / margin of the half-width or half-height.
    assert ndc.max() == pytest.approx(1 / margin, abs=1e-6)
    # The camera sits front-left (-Y, +X) and above the box centre.
    offset = np.subtract(camera.position, camera.focal_point)
    assert offset[0] > 0 and offset[1] < 0 and offset[2] > 0


def walking_track(frames: int = 10, metres: float = 3.0) -> MeshTrack:
    base = triangle().frame_verts(0)
    shift = np.zeros((frames, 1, 3), np.float32)
    shift[:, 0, 1] = -np.linspace(0, metres, frames)
    shift[:, 0, 2] = np.linspace(0, 0.5, frames)  # a jump: the camera must not bob with it
    return MeshTrack(base[None] + shift, np.array([[0, 1, 2]]))


def test_follow_offsets_and_travel_detection():
    track = walking_track()
    offsets = follow_offsets([[track]], 10)
    np.testing.assert_allclose(offsets[:, 1], -np.linspace(0, 3, 10), atol=1e-6)
    np.testing.assert_allclose(offsets[:, [0, 2]], 0, atol=1e-7)
    assert travels([[track]], 10)
    assert not travels([[walking_track(metres=1.0)]], 10)  # less than its own 2 m width


def test_frame_cameras_follow_by_default_only_when_travelling(front_camera):
    track = walking_track()
    cams = frame_cameras([[track]], (160, 120), list(range(10)), 10)
    shift = np.subtract(cams(9).position, cams(0).position)
    np.testing.assert_allclose(shift, [0, -3, 0], atol=1e-6)
    np.testing.assert_allclose(np.subtract(cams(9).focal_point, cams(0).focal_point), [0, -3, 0], atol=1e-6)
    fixed = frame_cameras([[track]], (160, 120), [2, 5], 10, camera=front_camera)
    assert fixed(9) == front_camera
    followed = frame_cameras([[track]], (160, 120), [2, 5], 10, camera=front_camera, follow=True)
    assert followed(2) == front_camera  # exact at the first rendered frame
    np.testing.assert_allclose(np.subtract(followed(5).position, front_camera.position), [0, -1, 0], atol=1e-6)


def test_track_broadcasts_static_frames_and_defaults_clim():
    track = triangle(scalars=np.array([2.0, 4.0, 3.0]))
    assert track.num_frames == 1 and track.verts.dtype == np.float32 and track.faces.dtype == np.int64
    assert track.clim == (2.0, 4.0)
    np.testing.assert_array_equal(track.frame_scalars(7), [2, 4, 3])
    assert triangle(scalars=np.full(3, 5.0)).clim == (4.5, 5.5)
    assert triangle(scalars=np.zeros(3), clim=(0, 10)).clim == (0.0, 10.0)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(faces=np.array([[0, 1, 3]])), "faces index vertices 0..3, the mesh has 3"),
        (dict(faces=np.array([[0.0, 1.0, 2.0]])), "faces must be integers"),
        (dict(verts=np.zeros((3, 2))), r"verts must have shape \(T, V, 3\)"),
        (dict(verts=np.full((3, 3), np.nan)), "NaN"),
        (dict(scalars=np.zeros(4)), r"scalars must have shape \(1, 3\) or \(3,\)"),
        (dict(scalars=np.zeros(3), clim=(1, 1)), "low < high"),
        (dict(scalars=np.zeros(3), cmap="nope"), "unknown colormap 'nope'"),
        (dict(color=(2, 0, 0)), r"color must be 3 numbers in \[0, 1\]"),
        (dict(opacity=0.0), "opacity"),
    ],
)
def test_track_errors_name_the_track_and_problem(kwargs, message):
    args = dict(verts=triangle().verts[0], faces=np.array([[0, 1, 2]]), label="skirt")
    args.update(kwargs)
    with pytest.raises(InputError, match=message) as err:
        MeshTrack(**args)
    assert "track 'skirt'" in str(err.value)


def test_check_panels():
    static, moving = triangle(), walking_track(frames=4)
    assert check_panels([[static], [moving, static]]) == 4
    longer = walking_track(frames=10)
    assert check_panels([[moving], [longer]]) == 10  # the shorter one holds its last frame
    assert np.array_equal(moving.frame_verts(9), moving.verts[3]) and np.array_equal(longer.frame_verts(9), longer.verts[9])
    with pytest.raises(InputError, match="wrap a single track"):
        check_panels([static, moving])
    with pytest.raises(InputError, match="non-empty list"):
        check_panels([])
