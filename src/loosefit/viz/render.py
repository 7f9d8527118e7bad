"""Render panels of mesh sequences offscreen to images, PNG, MP4 or GIF.

Backends: pyvista / VTK offscreen (fast, smooth shading) and a matplotlib fallback (software,
flat shading) used when VTK cannot open an offscreen context, or on request. Both give the same
image size and framing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from loosefit.errors import InputError
from loosefit.viz.scene import Camera, Panel, check_panels, frame_cameras
from loosefit.viz.writers import FrameWriter, save_png

__all__ = ["BACKENDS", "iter_frames", "render_frames", "render_video", "save_png", "select_backend"]

BACKENDS = ("auto", "pyvista", "matplotlib")
DEFAULT_SIZE = (640, 480)
BACKGROUND = (1.0, 1.0, 1.0)


def select_backend(backend: str = "auto") -> str:
    """The backend to use: ``"pyvista"`` or ``"matplotlib"``; ``"auto"`` picks pyvista when VTK can
    render offscreen here (probed once per process), else matplotlib."""
    if backend not in BACKENDS:
        raise InputError(f"unknown render backend {backend!r}, expected one of {BACKENDS}")
    if backend != "auto":
        return backend
    from loosefit.viz.pyvista_backend import pyvista_works

    return "pyvista" if pyvista_works() else "matplotlib"


def _check_size(size) -> tuple[int, int]:
    if len(size) != 2 or not all(isinstance(s, (int, np.integer)) and 8 <= s <= 8192 for s in size):
        raise InputError(f"image size must be (W, H) integers in [8, 8192], got {size!r}")
    return int(size[0]), int(size[1])


def _frame_indices(frames, num_frames: int) -> list[int]:
    if frames is None:
        return list(range(num_frames))
    if isinstance(frames, slice):
        indices = list(range(num_frames))[frames]
    else:
        indices = [int(f) for f in np.atleast_1d(np.asarray(frames))]
    bad = [f for f in indices if not 0 <= f < num_frames]
    if bad or not indices:
        raise InputError(f"frames {bad or frames} out of range: the sequence has {num_frames} frames")
    return indices


def iter_frames(
    panels: Sequence[Panel],
    size: tuple[int, int] = DEFAULT_SIZE,
    camera: Camera | None = None,
    frames=None,
    titles: Sequence[str] | None = None,
    follow: bool | None = None,
    backend: str = "auto",
    background=BACKGROUND,
) -> Iterator[np.ndarray]:
    """Render frame after frame, yielding ``(H, W * P, 3)`` uint8 images (P panels side by side).

    Args:
        panels: P panels, each a list of :class:`~loosefit.viz.scene.MeshTrack` drawn together
            (e.g. ``[[body, garment], [body, predicted]]``). Tracks have T frames or 1 (static).
        size: ``(W, H)`` pixels of one panel.
        camera: one camera for every panel; None: front-left, slightly above, framing every
            rendered frame of every panel (:func:`loosefit.viz.scene.fit_camera`).
        frames: frame indices (sequence or slice) to render; None for all T.
        titles: P panel titles; None: each panel's track labels joined by " + ".
        follow: move the camera with the first track's horizontal travel; None: only when the
            default camera is used and the first track travels farther than its own size.
        backend: ``"auto"``, ``"pyvista"`` or ``"matplotlib"``.
        background: RGB in ``[0, 1]``.
    """
    num_frames = check_panels(panels)
    size = _check_size(size)
    indices = _frame_indices(frames, num_frames)
    if titles is None:
        titles = [" + ".join(t.label for t in panel if t.label) for panel in panels]
    if len(titles) != len(panels):
        raise InputError(f"{len(titles)} titles for {len(panels)} panels")
    background = np.asarray(background, dtype=np.float64)
    if background.shape != (3,) or not ((background >= 0) & (background <= 1)).all():
        raise InputError(f"background must be 3 numbers in [0, 1], got {background.tolist()}")
    background = tuple(background.tolist())
    cameras = frame_cameras(panels, size, indices, num_frames, camera, follow)
    if select_backend(backend) == "pyvista":
        from loosefit.viz.pyvista_backend import PyVistaRenderer as Renderer
    else:
        from loosefit.viz.matplotlib_backend import MatplotlibRenderer as Renderer
    # Everything above runs at the call, so bad arguments fail before any frame is rendered.
    return _generate(Renderer, (panels, size, list(titles), background), indices, cameras)


def _generate(renderer_class, renderer_args, indices: list[int], cameras) -> Iterator[np.ndarray]:
    renderer = renderer_class(*renderer_args)
    try:
        for t in indices:
            yield renderer.render(t, cameras(t))
    finally:
        renderer.close()


def render_frames(panels: Sequence[Panel], size: tuple[int, int] = DEFAULT_SIZE, camera: Camera | None = None, frames=None, **options) -> np.ndarray:
    """All rendered frames at once: ``(N, H, W * P, 3)`` uint8 (N selected frames, P panels).

    Same arguments as :func:`iter_frames`; prefer :func:`render_video` for long sequences.
    """
    return np.stack(list(iter_frames(panels, size, camera, frames, **options)))


def render_video(
    panels: Sequence[Panel],
    path,
    fps: float = 30.0,
    size: tuple[int, int] = DEFAULT_SIZE,
    camera: Camera | None = None,
    frames=None,
    progress: bool = True,
    **options,
) -> Path:
    """Render to ``path``: ``.mp4`` (H.264, yuv420p), ``.gif``, ``.png`` (one frame) or a folder of
    PNGs (no suffix). Frames stream to the writer one by one; the file appears only when complete.

    Args:
        fps: frame rate of the video (the sequence's own, usually 30).
        progress: show a progress bar.
        Other arguments as :func:`iter_frames`.

    Returns:
        ``path``.
    """
    from tqdm import tqdm

    path = Path(path)
    total = len(_frame_indices(frames, check_panels(panels)))
    if path.suffix.lower() == ".png" and total != 1:
        raise InputError("a .png output holds one frame: select one (frames=[i]) or write a folder", path)
    with FrameWriter(path, fps) as writer:
        images = iter_frames(panels, size, camera, frames, **options)
        for image in tqdm(images, total=total, desc=f"render {path.name}", unit="frame", disable=not progress, leave=False):
            writer.write(image)
    return path
