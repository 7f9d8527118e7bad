"""Offscreen rendering of body and garment sequences to PNG, MP4 and GIF (pyvista/VTK, matplotlib fallback)."""

from loosefit.viz.render import iter_frames, render_frames, render_video, save_png
from loosefit.viz.scene import BODY_COLOR, GARMENT_COLOR, Camera, MeshTrack

__all__ = [
    "BODY_COLOR",
    "GARMENT_COLOR",
    "Camera",
    "MeshTrack",
    "iter_frames",
    "render_frames",
    "render_video",
    "save_png",
]
