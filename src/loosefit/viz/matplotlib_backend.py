"""Software fallback renderer with matplotlib (Agg): no OpenGL needed.

Triangles are projected with the same pinhole camera as the VTK backend
(:meth:`loosefit.viz.scene.Camera.project`), so both backends frame a scene identically, then
drawn far to near (painter's order) as one 2-D polygon collection per panel, each face shaded
flat with the lights of :mod:`loosefit.viz.shading`. Slower than VTK (about 0.3 s of CPU per
640x480 frame of the body and a 3k-vertex garment), but it runs anywhere.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from loosefit.geometry.normals import face_cross
from loosefit.viz.scene import Camera, Panel
from loosefit.viz.shading import lambert

DPI = 100
TEXT_FONT_SIZE = 8
TEXT_COLOR = (0.1, 0.1, 0.1)
NEAR = 1e-3
EDGE_WIDTH = 0.3  # points


class MatplotlibRenderer:
    """Renders panels side by side into ``(H, W * P, 3)`` uint8 images (same arguments as
    :class:`loosefit.viz.pyvista_backend.PyVistaRenderer`)."""

    def __init__(self, panels: Sequence[Panel], size: tuple[int, int], titles: Sequence[str], background):
        from loosefit.extras import require

        matplotlib = require("matplotlib", "rendering with matplotlib")
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        width, height = size
        self.panels = panels
        self.size = size
        self.figure = Figure(figsize=(width * len(panels) / DPI, height / DPI), dpi=DPI, facecolor=background)
        self.canvas = FigureCanvasAgg(self.figure)
        self.axes = []
        self.collections = [None] * len(panels)
        self.colormaps = [[matplotlib.colormaps[t.cmap] if t.scalars is not None else None for t in p] for p in panels]
        for i, (panel, title) in enumerate(zip(panels, titles)):
            ax = self.figure.add_axes((i / len(panels), 0.0, 1.0 / len(panels), 1.0))
            ax.set_xlim(0, width)
            ax.set_ylim(height, 0)
            ax.set_axis_off()
            ax.set_facecolor(background)
            if title:
                ax.text(width / 2, 4, title, ha="center", va="top", fontsize=TEXT_FONT_SIZE, color=TEXT_COLOR)
            for track in panel:
                if track.scalars is not None:
                    self._add_color_bar(i, track)
            self.axes.append(ax)

    def _add_color_bar(self, panel_index: int, track) -> None:
        import matplotlib.cm
        import matplotlib.colors

        share = 1.0 / len(self.panels)
        bar_ax = self.figure.add_axes((share * (panel_index + 0.86), 0.12, share * 0.03, 0.7))
        mappable = matplotlib.cm.ScalarMappable(matplotlib.colors.Normalize(*track.clim), track.cmap)
        bar = self.figure.colorbar(mappable, cax=bar_ax)
        bar.set_ticks(np.linspace(*track.clim, 3))
        bar.ax.tick_params(labelsize=TEXT_FONT_SIZE - 1, colors=TEXT_COLOR, length=2)
        bar.outline.set_visible(False)
        if track.scalar_name:
            bar_ax.set_title(track.scalar_name, fontsize=TEXT_FONT_SIZE - 1, color=TEXT_COLOR)

    def _panel_polygons(self, i: int, t: int, camera: Camera):
        """Projected triangles of panel ``i`` at frame ``t``, far to near, with RGBA colours and edge widths."""
        basis = camera.basis()
        eye = np.asarray(camera.position, np.float64)
        polys, depths, colors, widths = [], [], [], []
        for track, cmap in zip(self.panels[i], self.colormaps[i]):
            verts = track.frame_verts(t).astype(np.float64)
            pixels, depth = camera.project(verts, self.size)
            faces = track.faces
            face_depth = depth[faces]
            visible = (face_depth > NEAR).all(axis=1)
            faces = faces[visible]
            centres = verts[faces].mean(axis=1)
            brightness = lambert(face_cross(verts, faces), eye - centres, basis)  # area-weighted face normals
            scalars = track.frame_scalars(t)
            if scalars is None:
                base = np.broadcast_to(np.asarray(track.color), (faces.shape[0], 3))
            else:
                low, high = track.clim
                base = cmap(np.clip((scalars[faces].mean(axis=1) - low) / (high - low), 0.0, 1.0))[:, :3]
            rgba = np.empty((faces.shape[0], 4))
            rgba[:, :3] = np.clip(base * brightness[:, None], 0.0, 1.0)
            rgba[:, 3] = track.opacity
            polys.append(pixels[faces])
            depths.append(face_depth[visible].mean(axis=1))
            colors.append(rgba)
            # Edges in the face colour close the hairline cracks between anti-aliased neighbours;
            # on translucent faces they would show as a darker wireframe.
            widths.append(np.full(faces.shape[0], EDGE_WIDTH if track.opacity == 1.0 else 0.0))
        order = np.argsort(-np.concatenate(depths), kind="stable")
        return np.concatenate(polys)[order], np.concatenate(colors)[order], np.concatenate(widths)[order]

    def render(self, t: int, camera: Camera) -> np.ndarray:
        """``(H, W * P, 3)`` uint8 image of frame ``t`` seen by ``camera`` in every panel."""
        from matplotlib.collections import PolyCollection

        for i, ax in enumerate(self.axes):
            if self.collections[i] is not None:
                self.collections[i].remove()
            polys, colors, widths = self._panel_polygons(i, t, camera)
            collection = PolyCollection(polys, facecolors=colors, edgecolors=colors, linewidths=widths, antialiaseds=False)
            ax.add_collection(collection)
            self.collections[i] = collection
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[:, :, :3].copy()

    def close(self) -> None:
        self.figure.clear()
