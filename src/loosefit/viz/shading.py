"""Lighting shared by the render backends, and the vertex / face normals it needs.

Lights are fixed to the camera (they move with it), given as directions in camera coordinates
(x right, y up, z towards the viewer): a key light from the upper left that rakes across folds,
and a weaker fill from the right so that shadowed sides keep some shape, plus ambient.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

#: ``(direction in camera coordinates, intensity)`` of each light.
LIGHTS = (
    ((-0.55, 0.65, 1.0), 0.85),
    ((0.80, -0.10, 1.0), 0.30),
)
AMBIENT = 0.22
DIFFUSE = 0.80
SPECULAR = 0.08
SPECULAR_POWER = 20.0


def face_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(F, 3)`` area-weighted face normals (length = twice the triangle's area) of ``verts (V, 3)``."""
    v0, v1, v2 = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    return np.cross(v1 - v0, v2 - v0)


class VertexNormals:
    """Unit vertex normals of a fixed triangulation: area-weighted sums of the adjacent faces' normals.

    The vertex-face incidence matrix is built once, so each frame costs one sparse product.
    """

    def __init__(self, faces: np.ndarray, num_verts: int):
        self.faces = faces
        rows = faces.reshape(-1)
        cols = np.repeat(np.arange(faces.shape[0]), 3)
        self.incidence = scipy.sparse.csr_matrix(
            (np.ones(rows.shape[0], np.float32), (rows, cols)), shape=(num_verts, faces.shape[0])
        )

    def __call__(self, verts: np.ndarray) -> np.ndarray:
        """``(V, 3)`` float32 unit normals of ``verts (V, 3)``; isolated vertices get ``+Z``."""
        normals = np.asarray(self.incidence @ face_normals(verts, self.faces), dtype=np.float32)
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        isolated = length[:, 0] < 1e-20
        normals[isolated] = (0.0, 0.0, 1.0)
        length[isolated] = 1.0
        return normals / length


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
