"""Lighting shared by the render backends, and the vertex normals it needs.

Lights are fixed to the camera (they move with it), given as directions in camera coordinates
(x right, y up, z towards the viewer): a key light from the upper left that rakes across folds,
and a weaker fill from the right so that shadowed sides keep some shape, plus ambient.
"""

from __future__ import annotations

import numpy as np

from loosefit.geometry.normals import vertex_incidence, vertex_normals

#: ``(direction in camera coordinates, intensity)`` of each light.
LIGHTS = (
    ((-0.55, 0.65, 1.0), 0.85),
    ((0.80, -0.10, 1.0), 0.30),
)
AMBIENT = 0.22
DIFFUSE = 0.80
SPECULAR = 0.08
SPECULAR_POWER = 20.0


class VertexNormals:
    """Unit vertex normals of a fixed triangulation for shading: area-weighted
    (:func:`~loosefit.geometry.normals.vertex_normals`), with the vertex-face incidence built once, so each
    frame costs one sparse product.
    """

    def __init__(self, faces: np.ndarray, num_verts: int):
        self.faces = np.asarray(faces, np.int64)
        self.incidence = vertex_incidence(self.faces, num_verts)

    def __call__(self, verts: np.ndarray) -> np.ndarray:
        """``(V, 3)`` float32 unit normals of ``verts (V, 3)``; isolated vertices (and those of degenerate faces
        only) get ``+Z``, which a renderer can normalise."""
        normals = vertex_normals(verts, self.faces, incidence=self.incidence)
        normals[~normals.any(axis=1)] = (0.0, 0.0, 1.0)
        return normals


def world_lights(camera_basis: np.ndarray) -> list[tuple[np.ndarray, float]]:
    """The :data:`LIGHTS` as unit world directions (towards the light) for a camera basis
    ``(3, 3)`` (rows right, up, back; see :meth:`loosefit.viz.scene.Camera.basis`)."""
    lights = []
    for direction, intensity in LIGHTS:
        d = np.asarray(direction, np.float64) @ camera_basis
        lights.append((d / np.linalg.norm(d), intensity))
    return lights


def lambert(normals: np.ndarray, to_eye: np.ndarray, camera_basis: np.ndarray) -> np.ndarray:
    """``(N,)`` brightness ``AMBIENT + DIFFUSE * sum(intensity * max(0, n . l))`` of two-sided surfaces.

    Args:
        normals: ``(N, 3)`` surface normals (any length).
        to_eye: ``(N, 3)`` directions from the surface towards the eye; normals facing away are
            flipped, so that the inside of an open garment is lit like its outside.
        camera_basis: ``(3, 3)`` camera axes.
    """
    n = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-20)
    n = np.where((np.einsum("ij,ij->i", n, to_eye) < 0)[:, None], -n, n)
    light = np.zeros(n.shape[0])
    for direction, intensity in world_lights(camera_basis):
        light += intensity * np.clip(n @ direction, 0.0, None)
    return AMBIENT + DIFFUSE * light
