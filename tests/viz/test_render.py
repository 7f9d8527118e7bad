"""Rendering known scenes with both backends and checking pixels against the camera model."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from scipy.ndimage import binary_dilation

from loosefit.errors import InputError
from loosefit.viz import pyvista_backend
from loosefit.viz.render import iter_frames, render_frames, render_video, select_backend
from loosefit.viz.scene import BODY_COLOR, MeshTrack, fit_camera
from loosefit.viz.shading import AMBIENT, DIFFUSE, LIGHTS, lambert
from tests.viz.conftest import SIZE, centroid, pixel, triangle

BACKENDS = ["pyvista", "matplotlib"]
WHITE = [255, 255, 255]
# The triangle faces the camera, so its normal is the camera's z axis: brightness in closed form.
FACING = AMBIENT + DIFFUSE * sum(i * d[2] / np.linalg.norm(d) for d, i in LIGHTS)


def lit(rgb) -> np.ndarray:
    return np.clip(np.asarray(rgb) * FACING, 0, 1) * 255


@pytest.mark.parametrize("backend", BACKENDS)
def test_red_triangle_facing_the_camera(backend, front_camera):
    tri = triangle()
    image = render_frames([[tri]], SIZE, front_camera, backend=backend)
    assert image.shape == (1, SIZE[1], SIZE[0], 3) and image.dtype == np.uint8
    np.testing.assert_allclose(pixel(image[0], front_camera, centroid(tri)), lit([1, 0, 0]), atol=10)
    # Background outside the triangle: the corners and beside the base.
    for row, col in [(2, 2), (2, 157), (117, 2), (117, 157), (100, 20), (100, 140)]:
        np.testing.assert_array_equal(image[0, row, col], WHITE)


def test_backends_agree_on_size_and_silhouette(front_camera):
    tri = triangle()
    images = [render_frames([[tri]], SIZE, front_camera, backend=b, titles=[""])[0] for b in BACKENDS]
    masks = [(im < 200).any(axis=2) for im in images]
    assert images[0].shape == images[1].shape
    # The silhouettes agree to within two pixels (sharp corners): each lies inside the other grown by two.
    grown = [binary_dilation(m, np.ones((5, 5), bool)) for m in masks]
    assert not (masks[0] & ~grown[1]).any() and not (masks[1] & ~grown[0]).any()
    # The silhouette is where the camera model puts the corners.
    corners, _ = front_camera.project(tri.frame_verts(0), SIZE)
    rows, cols = np.nonzero(masks[0])
    np.testing.assert_allclose([cols.min(), cols.max(), rows.min(), rows.max()],
                               [corners[0, 0], corners[1, 0], corners[2, 1], corners[0, 1]], atol=2)


@pytest.mark.parametrize("backend", BACKENDS)
def test_two_panels_side_by_side_share_the_camera(backend, front_camera):
    red, blue = triangle((1, 0, 0), label="red"), triangle((0, 0, 1), label="blue")
    image = render_frames([[red], [blue]], SIZE, front_camera, backend=backend)[0]
    assert image.shape == (SIZE[1], 2 * SIZE[0], 3)
    np.testing.assert_allclose(pixel(image[:, : SIZE[0]], front_camera, centroid(red)), lit([1, 0, 0]), atol=10)
    np.testing.assert_allclose(pixel(image[:, SIZE[0] :], front_camera, centroid(blue)), lit([0, 0, 1]), atol=10)
    # Titles ("red", "blue") are drawn in the top rows of each panel, and only when asked for.
    untitled = render_frames([[red], [blue]], SIZE, front_camera, backend=backend, titles=["", ""])[0]
    for half in (slice(0, SIZE[0]), slice(SIZE[0], None)):
        assert (image[:12, half] < 128).any() and (untitled[:12, half] == 255).all()


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("value", [0.0, 0.5, 1.0])
def test_scalars_map_to_the_colormap(backend, value, front_camera):
    tri = triangle(scalars=np.full(3, 10.0 * value), clim=(0.0, 10.0), cmap="viridis", scalar_name="mm")
    image = render_frames([[tri]], SIZE, front_camera, backend=backend)[0]
    expected = lit(matplotlib.colormaps["viridis"](value)[:3])
    np.testing.assert_allclose(pixel(image, front_camera, centroid(tri)), expected, atol=10)
    # The colour bar: its top colour (the colormap's maximum, yellow) appears in the right part of the panel.
    top = np.array(matplotlib.colormaps["viridis"](1.0)[:3]) * 255
    assert (np.abs(image[:, 120:].astype(float) - top).max(axis=2) < 12).any()


@pytest.mark.parametrize("backend", BACKENDS)
def test_translucent_track_blends_with_what_is_behind(backend, front_camera):
    red, glass = triangle((1, 0, 0)), triangle((0, 0, 1), opacity=0.5)
    glass.verts[..., 1] -= 0.5  # in front of the red one
    image = render_frames([[red, glass]], SIZE, front_camera, backend=backend)[0]
    expected = 0.5 * lit([0, 0, 1]) + 0.5 * lit([1, 0, 0])
    np.testing.assert_allclose(pixel(image, front_camera, centroid(red)), expected, atol=10)


@pytest.mark.parametrize("backend", BACKENDS)
def test_body_silhouette_is_framed_by_the_default_camera(backend, body):
    track = MeshTrack(body.rest_verts(), body.faces, BODY_COLOR)
    image = render_frames([[track]], SIZE, backend=backend)[0]
    camera = fit_camera([[track]], SIZE, [0])
    projected, _ = camera.project(body.rest_verts(), SIZE)
    rows, cols = np.nonzero((image < 230).any(axis=2))
    np.testing.assert_allclose([cols.min(), cols.max(), rows.min(), rows.max()],
                               [*np.percentile(projected[:, 0], [0, 100]), *np.percentile(projected[:, 1], [0, 100])], atol=2.5)
    assert rows.max() - rows.min() > 0.8 * SIZE[1]  # a tight fit: the body fills the height


def test_auto_falls_back_to_matplotlib_without_an_offscreen_context(monkeypatch, front_camera):
    monkeypatch.setattr(pyvista_backend, "pyvista_works", lambda: False)
    assert select_backend("auto") == "matplotlib"
    tri = triangle()
    np.testing.assert_array_equal(render_frames([[tri]], SIZE, front_camera), render_frames([[tri]], SIZE, front_camera, backend="matplotlib"))


def test_offscreen_probe_detects_vtk():
    # The rest of this file renders with VTK in this process, so the probe must see it working.
    assert pyvista_backend.pyvista_works() and select_backend() == "pyvista"


def moving_triangle(frames: int = 3) -> MeshTrack:
    verts = np.repeat(triangle().verts, frames, axis=0)
    verts[:, :, 2] += np.linspace(0, 0.2, frames)[:, None]
    return MeshTrack(verts, triangle().faces, color=(1, 0, 0))


def test_frames_selection_and_streaming(front_camera):
    track = moving_triangle(4)
    frames = list(iter_frames([[track]], SIZE, front_camera, frames=[3, 1], backend="pyvista"))
    every = render_frames([[track]], SIZE, front_camera, backend="pyvista")
    assert len(frames) == 2
    np.testing.assert_array_equal(frames[0], every[3])
    np.testing.assert_array_equal(frames[1], every[1])
    # The triangle moves up 0.2 m: its top corner climbs by the projected amount.
    tops = [np.nonzero((im < 200).any(axis=2))[0].min() for im in every[[0, 3]]]
    expected = np.diff(front_camera.project(np.array([[0, 0, 1.0], [0, 0, 1.2]]), SIZE)[0][:, 1])[0]
    assert tops[1] - tops[0] == pytest.approx(expected, abs=1.5)


@pytest.mark.parametrize("backend", BACKENDS)
def test_shading_follows_the_turning_surface(backend, front_camera):
    # The triangle turns about Z frame by frame; the normals updated in place must dim it as the
    # closed-form two-sided Lambert term says.
    angles = np.radians([0.0, 35.0, 70.0])
    c, s = np.cos(angles), np.sin(angles)
    rot = np.stack([np.stack([c, -s, 0 * c], 1), np.stack([s, c, 0 * c], 1), np.tile([0.0, 0.0, 1.0], (3, 1))], 1)
    verts = np.einsum("tij,vj->tvi", rot, triangle().frame_verts(0)).astype(np.float32)
    track = MeshTrack(verts, triangle().faces, color=(1, 1, 1))
    images = render_frames([[track]], SIZE, front_camera, backend=backend)
    eye = np.asarray(front_camera.position)
    for t in range(3):
        normal = np.cross(verts[t, 1] - verts[t, 0], verts[t, 2] - verts[t, 0])[None]
        centre = verts[t].mean(axis=0, keepdims=True)
        expected = min(lambert(normal, eye - centre, front_camera.basis())[0], 1.0) * 255
        np.testing.assert_allclose(pixel(images[t], front_camera, centre), [expected] * 3, atol=12)


@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_render_video_round_trip(tmp_path, suffix, front_camera):
    import imageio.v3 as iio

    path = render_video([[moving_triangle(3)]], tmp_path / f"clip{suffix}", fps=10, size=SIZE, camera=front_camera, progress=False)
    frames = iio.imread(path, index=None)
    assert frames.shape[:3] == (3, SIZE[1], SIZE[0])
    centre = pixel(frames[0][..., :3], front_camera, centroid(triangle()))
    np.testing.assert_allclose(centre, lit([1, 0, 0]), atol=16)  # lossy codecs
    assert [p.name for p in tmp_path.iterdir()] == [f"clip{suffix}"]  # no temporary left over


def test_bad_arguments_raise_clear_errors(tmp_path, front_camera):
    tri = triangle()
    with pytest.raises(InputError, match="a .png output holds one frame"):
        render_video([[moving_triangle(2)]], tmp_path / "still.png", camera=front_camera)
    assert not (tmp_path / "still.png").exists()
    with pytest.raises(InputError, match="out of range: the sequence has 1 frames"):
        render_frames([[tri]], SIZE, front_camera, frames=[1])
    with pytest.raises(InputError, match="out of range"):
        render_frames([[tri]], SIZE, front_camera, frames=slice(5, None))
    with pytest.raises(InputError, match="unknown render backend 'opengl'"):
        render_frames([[tri]], SIZE, front_camera, backend="opengl")
    with pytest.raises(InputError, match=r"image size must be \(W, H\)"):
        render_frames([[tri]], (0, 10), front_camera)
    with pytest.raises(InputError, match="2 titles for 1 panels"):
        render_frames([[tri]], SIZE, front_camera, titles=["a", "b"])
    with pytest.raises(InputError, match="wrap a single track"):
        render_frames([tri], SIZE, front_camera)
    with pytest.raises(InputError, match="background"):
        render_frames([[tri]], SIZE, front_camera, background=(255, 255, 255))
