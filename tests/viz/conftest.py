"""Small known scenes for the rendering tests."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.viz.scene import Camera, MeshTrack

SIZE = (160, 120)


def triangle(color=(1.0, 0.0, 0.0), x_offset: float = 0.0, **look) -> MeshTrack:
    """A triangle in the plane y = 0 facing -Y (towards :func:`front_camera`), 2 m wide, 2 m high."""
    verts = np.array([[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [0.0, 0.0, 1.0]], np.float32)
    verts[:, 0] += x_offset
    return MeshTrack(verts, np.array([[0, 1, 2]]), color=color, **look)


def centroid(track: MeshTrack) -> np.ndarray:
    return track.frame_verts(0).mean(axis=0, keepdims=True)


@pytest.fixture
def front_camera() -> Camera:
    """Looking at the origin along +Y from 5 m in front (the body's front is -Y)."""
    return Camera((0.0, -5.0, 0.0), (0.0, 0.0, 0.0))


def pixel(image: np.ndarray, camera: Camera, point: np.ndarray, size=SIZE) -> np.ndarray:
    """The RGB of ``image`` at the projection of ``point (1, 3)``."""
    (col, row), = camera.project(point, size)[0]
    return image[int(row), int(col)].astype(int)
