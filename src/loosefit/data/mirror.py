"""Left-right mirrored garment frames: the simulated garment of a mirrored motion, on the garment's own mesh.

A garment mesh is rarely symmetric vertex for vertex, so the mirror image of a frame is read back onto the mesh
through a fixed correspondence (:class:`GarmentMirror`): vertex ``i`` takes the place of the mirror image of the
garment's surface point nearest to ``i``'s own mirror image at rest,

    X'_i(t) = M sum_k b_ik X_{f_ik}(t),      M = diag(-1, 1, 1),

with ``(f_i, b_i)`` the rest surface's closest triangle and barycentric coordinates of ``M x_i``. On a garment
that is symmetric as a surface this is exact up to the linear interpolation inside a triangle; on one that is
not, ``asymmetry`` (how far each vertex's mirror image is from the rest surface) says by how much the mirrored
frames describe another garment. With :func:`loosefit.motion.mirror.mirror_motion` for the body, a mirrored
sequence is a second training sequence from one simulation (a clockwise spin gives a counter-clockwise one).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loosefit.errors import InputError
from loosefit.motion.mirror import REFLECTION

#: The name of a sequence's mirror: ``<sequence>=mirrored`` (for its bone transforms in a prepared store).
MIRRORED = "=mirrored"


@dataclass(frozen=True)
class GarmentMirror:
    """A garment mesh's left-right correspondence through ``x = 0``.

    Attributes:
        faces: ``(F, 3)`` int64, the garment's triangles.
        face: ``(V,)`` int64, the rest triangle nearest to each vertex's mirror image.
        bary: ``(V, 3)`` float64, barycentric coordinates of that nearest point.
        asymmetry: ``(V,)`` float64, m: each vertex's mirror image's distance from the rest surface.
    """

    faces: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    asymmetry: np.ndarray

    @classmethod
    def build(cls, rest_verts: np.ndarray, faces: np.ndarray) -> "GarmentMirror":
        """The correspondence of a garment at rest, ``rest_verts (V, 3)`` m (on a body symmetric about ``x = 0``)."""
        from loosefit.geometry.features import closest_body_points

        rest = np.asarray(rest_verts, np.float64)
        faces = np.asarray(faces, np.int64)
        image = rest @ REFLECTION
        face, bary = closest_body_points(image, rest, faces)
        nearest = np.einsum("vk,vkd->vd", bary, rest[faces[face]])
        return cls(faces, face, bary, np.linalg.norm(nearest - image, axis=1))

    def __call__(self, frames: np.ndarray) -> np.ndarray:
        """Mirrored ``frames (..., V, 3)`` -> ``(..., V, 3)`` float32, m."""
        frames = np.asarray(frames)
        if frames.shape[-2:] != (len(self.face), 3):
            raise InputError(f"frames of {frames.shape[-2]} vertices for a garment of {len(self.face)}")
        corners = frames[..., self.faces[self.face], :]  # (..., V, 3 corners, 3)
        points = np.einsum("vk,...vkd->...vd", self.bary, corners.astype(np.float64))
        return (points @ REFLECTION).astype(np.float32)


class MirroredSequence:
    """A stored sequence's mirror, read through a :class:`GarmentMirror` as it is read (``name``, ``num_frames``
    and ``verts`` indexed like the stored array: ``verts[a:b]``, ``verts.oindex[frames]``)."""

    def __init__(self, sequence, mirror: GarmentMirror):
        self.name = sequence.name + MIRRORED
        self.num_frames = sequence.num_frames
        self.verts = _MirroredFrames(sequence.verts, mirror)


class _MirroredFrames:
    def __init__(self, frames, mirror: GarmentMirror):
        self._frames, self._mirror = frames, mirror

    def __getitem__(self, key) -> np.ndarray:
        return self._mirror(np.asarray(self._frames[key]))

    @property
    def oindex(self) -> "_MirroredFrames":
        return _MirroredFrames(self._frames.oindex, self._mirror)
