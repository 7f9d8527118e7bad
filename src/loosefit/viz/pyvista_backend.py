"""Offscreen rendering with pyvista / VTK (EGL or OSMesa; no display needed).

One Plotter with one subplot per panel is built once; each frame only moves the points (and
normals, scalars) of the existing meshes in place and sets the camera, then reads the pixels back.
"""

from __future__ import annotations

import functools
import subprocess
import sys
from typing import Callable, Sequence

import numpy as np

from loosefit.viz.scene import Camera, MeshTrack, Panel
from loosefit.viz.shading import AMBIENT, DIFFUSE, LIGHTS, SPECULAR, SPECULAR_POWER, VertexNormals

TEXT_FONT_SIZE = 11
#: Titles about 11 px high ("Hg"), like the matplotlib backend's 8 pt titles.
TITLE_FONT_SIZE = 5
MULTI_SAMPLES = 4
TEXT_COLOR = (0.1, 0.1, 0.1)


class PyVistaRenderer:
    """Renders panels side by side into ``(H, W * P, 3)`` uint8 images.

    Args:
        panels: P panels, each a list of :class:`~loosefit.viz.scene.MeshTrack`.
        size: ``(W, H)`` pixels of one panel.
        titles: P titles ("" for none).
        background: RGB in ``[0, 1]``.
    """

    def __init__(self, panels: Sequence[Panel], size: tuple[int, int], titles: Sequence[str], background):
        from loosefit.extras import require

        pv = require("pyvista", "offscreen rendering")
        width, height = size
        self.shape = (height, width * len(panels), 3)
        self.plotter = pv.Plotter(
            off_screen=True,
            shape=(1, len(panels)),
            window_size=(width * len(panels), height),
            border=False,
            lighting="none",
        )
        # 4x MSAA: edges close to 8x at 4/5 of its cost with Mesa's software rasteriser.
        self.plotter.ren_win.SetMultiSamples(MULTI_SAMPLES)
        self.plotter.set_background(background, all_renderers=True)
        self.updaters: list[Callable[[int], None]] = []
        self.renderers = []
        for i, (panel, title) in enumerate(zip(panels, titles)):
            self.plotter.subplot(0, i)
            self.renderers.append(self.plotter.renderer)
            for track in panel:
                self._add_track(pv, track)
            if title:
                self.plotter.add_text(title, position="upper_edge", font_size=TITLE_FONT_SIZE, color=TEXT_COLOR)
        for direction, intensity in LIGHTS:
            light = pv.Light(position=direction, focal_point=(0, 0, 0), light_type="camera light", intensity=intensity)
            self.plotter.add_light(light)

    def _add_track(self, pv, track: MeshTrack) -> None:
        faces_vtk = np.hstack([np.full((track.faces.shape[0], 1), 3, np.int64), track.faces]).reshape(-1)
        mesh = pv.PolyData(track.frame_verts(0).copy(), faces_vtk)
        normals = VertexNormals(track.faces, track.verts.shape[1])
        mesh.point_data["Normals"] = normals(track.frame_verts(0))
        mesh.point_data.active_normals_name = "Normals"
        style = dict(
            opacity=track.opacity,
            ambient=AMBIENT,
            diffuse=DIFFUSE,
            specular=SPECULAR,
            specular_power=SPECULAR_POWER,
            smooth_shading=False,  # we supply the vertex normals ourselves, updated every frame
            show_scalar_bar=False,
            lighting=True,
        )
        if track.scalars is None:
            actor = self.plotter.add_mesh(mesh, color=track.color, **style)
        else:
            mesh.point_data["scalars"] = track.frame_scalars(0).copy()
            actor = self.plotter.add_mesh(mesh, scalars="scalars", cmap=track.cmap, clim=track.clim, **style)
            self._add_scalar_bar(actor, track.scalar_name)
        actor.prop.interpolation = "phong"
        if track.opacity < 1.0:
            # Translucent surfaces blend in depth order with depth peeling, which needs MSAA off.
            self.plotter.ren_win.SetMultiSamples(0)
            self.plotter.enable_depth_peeling()
        if track.num_frames == 1 and (track.scalars is None or track.scalars.shape[0] == 1):
            return  # static: nothing to update per frame

        def update(t: int) -> None:
            verts = track.frame_verts(t)
            mesh.points[:] = verts
            mesh.point_data["Normals"][:] = normals(verts)
            if track.scalars is not None:
                mesh.point_data["scalars"][:] = track.frame_scalars(t)
            mesh.Modified()

        self.updaters.append(update)

    def _add_scalar_bar(self, actor, title: str) -> None:
        # A bar per subplot (pyvista's own scalar bars are shared by title across subplots).
        from vtkmodules.vtkRenderingAnnotation import vtkScalarBarActor

        bar = vtkScalarBarActor()
        bar.SetLookupTable(actor.mapper.GetLookupTable())
        bar.SetTitle(title)
        bar.SetNumberOfLabels(3)
        bar.SetLabelFormat("%.4g")
        bar.SetPosition(0.80, 0.12)
        bar.SetWidth(0.16)
        bar.SetHeight(0.7)
        bar.SetBarRatio(0.2)
        bar.SetVerticalTitleSeparation(4)
        bar.UnconstrainedFontSizeOn()
        for prop in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()):
            prop.SetColor(*TEXT_COLOR)
            prop.SetFontSize(TEXT_FONT_SIZE)
            prop.ShadowOff()
            prop.ItalicOff()
            prop.BoldOff()
        self.plotter.renderer.AddViewProp(bar)

    def render(self, t: int, camera: Camera) -> np.ndarray:
        """``(H, W * P, 3)`` uint8 image of frame ``t`` seen by ``camera`` in every panel."""
        for update in self.updaters:
            update(t)
        for renderer in self.renderers:
            # Through pyvista's camera, which marks it as set: otherwise the first render resets it.
            renderer.camera.position = camera.position
            renderer.camera.focal_point = camera.focal_point
            renderer.camera.up = camera.view_up
            renderer.camera.view_angle = camera.view_angle
            renderer.ResetCameraClippingRange()
        self.plotter.render()
        image = self.plotter.screenshot(return_img=True)
        if image.shape != self.shape:
            raise RuntimeError(f"VTK returned a {image.shape} image, expected {self.shape}")
        return image

    def close(self) -> None:
        self.plotter.close()


_PROBE = """
import numpy as np
from loosefit.viz.pyvista_backend import PyVistaRenderer
from loosefit.viz.scene import Camera, MeshTrack
track = MeshTrack(np.array([[-1, 0, -1], [1, 0, -1], [0, 0, 1]], np.float32), np.array([[0, 1, 2]]), color=(1, 0, 0))
renderer = PyVistaRenderer([[track]], (32, 32), [""], (1.0, 1.0, 1.0))
image = renderer.render(0, Camera((0, -5, 0), (0, 0, 0)))
r, g, b = image[16, 16].astype(int)
raise SystemExit(0 if r > 100 and g < 60 and b < 60 and (image[1, 1] > 200).all() else 3)
"""


@functools.cache
def pyvista_works() -> bool:
    """Whether VTK can render offscreen here, probed once per process in a child process
    (a missing GL context can abort the process rather than raise)."""
    try:
        result = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return result.returncode == 0
