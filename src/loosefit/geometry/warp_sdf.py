"""Signed distance to several frames of one closed triangle mesh (a posed body) at once, with Warp.

:class:`MotionMeshSDF` gives what :class:`~loosefit.geometry.signed_distance.BodySDF` of each frame gives (its
pseudonormal sign, and the winding number where asked), for the points of many frames in one kernel launch: each
frame's Warp BVH is refitted to the frame's vertices (0.6 ms for the 1,229-vertex proxy, against 1.5 ms to build
libigl's tree), the closest triangle is found over it in float32, and the closest point on that triangle, the
distance and the side are computed in float64. Distances equal libigl's to about 1e-7 m (a closer triangle missed
by float32 rounding is at most that much closer); the triangle and the point can differ from libigl's only where
two triangles are that close to equally near.
"""

from __future__ import annotations

import numpy as np

from loosefit.errors import InputError
from loosefit.extras import warp_kernels
from loosefit.geometry.normals import angle_weighted_normals


def available() -> bool:
    """Whether Warp and this module's kernel load."""
    return warp_kernels("loosefit.geometry._sdf_warp", "signed_closest") is not None


def _normals(verts: np.ndarray, faces: np.ndarray, corner_edge: np.ndarray, num_edges: int):
    """Unit face normals ``(T, F, 3)``, angle-weighted unit vertex normals ``(T, V, 3)`` and edge pseudonormals
    (the sum of the two faces' normals, ``(T, E, 3)``) of ``verts (T, V, 3)`` float64, as BodySDF computes them
    frame by frame with libigl."""
    T = len(verts)
    fn, vn = angle_weighted_normals(verts, faces)
    edge_of = (np.arange(T)[:, None, None] * num_edges + corner_edge[None]).reshape(-1)
    each = np.repeat(fn, 3, axis=1).reshape(-1, 3)
    en = np.stack([np.bincount(edge_of, each[:, k], T * num_edges) for k in range(3)], 1).reshape(T, num_edges, 3)
    return fn, vn, en


class MotionMeshSDF:
    """Signed distances (negative inside) to up to ``capacity`` frames of one closed, outward-oriented mesh, the
    frames set by :meth:`refit` and queried together by :meth:`query`.

    Args:
        faces: ``(F, 3)`` int triangles, counter-clockwise seen from outside.
        capacity: frames held at most (one Warp mesh each, refitted by every :meth:`refit`).
    """

    def __init__(self, faces: np.ndarray, capacity: int):
        kernels = warp_kernels("loosefit.geometry._sdf_warp", "signed_closest")
        if kernels is None:
            raise InputError("MotionMeshSDF needs warp (pip install warp-lang)")
        self._wp, self._kernel = kernels
        self.faces = np.ascontiguousarray(faces, np.int64)
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or len(self.faces) == 0:
            raise InputError(f"MotionMeshSDF needs faces (F, 3), got {self.faces.shape}")
        corner_edges = np.stack([self.faces[:, [1, 2]], self.faces[:, [2, 0]], self.faces[:, [0, 1]]], 1)
        _, corner_edge = np.unique(np.sort(corner_edges.reshape(-1, 2), 1), axis=0, return_inverse=True)
        self._corner_edge = corner_edge.reshape(-1, 3)  # edge opposite corner c of face f
        self.num_edges = int(corner_edge.max()) + 1
        self.capacity = int(capacity)
        self._meshes: list = []
        self.num_frames = 0
        wp = self._wp
        self._faces_wp = wp.array(self.faces.astype(np.int32).ravel(), dtype=wp.int32, device="cpu")
        self._corner_wp = wp.array(self._corner_edge.astype(np.int32).ravel(), dtype=wp.int32, device="cpu")

    def refit(self, verts: np.ndarray) -> "MotionMeshSDF":
        """Set the frames: ``verts (T, V, 3)`` metres, ``T <= capacity``. Returns self."""
        wp = self._wp
        v = np.ascontiguousarray(verts, np.float64)
        if v.ndim != 3 or v.shape[2] != 3 or not 0 < len(v) <= self.capacity or v.shape[1] <= self.faces.max():
            raise InputError(f"MotionMeshSDF takes 1 to {self.capacity} frames (T, V, 3) of its mesh, got {v.shape}")
        if self._meshes and self._meshes[0].points.shape[0] != v.shape[1]:
            raise InputError(f"MotionMeshSDF frames must keep {self._meshes[0].points.shape[0]} vertices, "
                             f"got {v.shape[1]}")
        v32 = v.astype(np.float32)
        for t in range(len(v)):
            if t < len(self._meshes):
                self._meshes[t].points.numpy()[:] = v32[t]
                self._meshes[t].refit()
            else:
                self._meshes.append(wp.Mesh(points=wp.array(v32[t], dtype=wp.vec3, device="cpu"),
                                            indices=self._faces_wp))
        self.num_frames = T = len(v)
        self.verts = v
        self.face_normals, vn, en = _normals(v, self.faces, self._corner_edge, self.num_edges)
        self._ids = wp.array(np.array([m.id for m in self._meshes[:T]], np.uint64), dtype=wp.uint64, device="cpu")
        self._verts_wp = wp.array(v.reshape(-1, 3), dtype=wp.vec3d, device="cpu")
        self._fn_wp, self._vn_wp, self._en_wp, self._low_wp, self._high_wp = (
            wp.array(a.reshape(-1, 3), dtype=wp.vec3d, device="cpu")
            for a in (self.face_normals, vn, en, v.min(axis=1), v.max(axis=1)))
        return self

    def query(self, points: np.ndarray, frame: np.ndarray, winding_from: float = np.inf,
              outside_beyond: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Signed distances of ``points (N, 3)`` (metres) to their frames ``frame (N,)`` (in ``[0, T)``).

        The side is the pseudonormal's (:class:`~loosefit.geometry.signed_distance.BodySDF`), except for a point
        it puts more than ``winding_from`` metres outside and at most ``outside_beyond (N,)`` metres (default:
        no limit), whose side is the frame's winding number: exact, from the triangles an axis ray from the point
        crosses (:meth:`BodySDF.inside` with libigl; Warp's fast winding number cost 2-3 times the closest point).

        Returns:
            ``dist (N,)`` float64 signed distances, ``closest (N, 3)`` float64 closest surface points, ``face (N,)``
            int64 their triangles.
        """
        wp = self._wp
        p = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 3))
        fr = np.ascontiguousarray(frame, np.int32).reshape(-1)
        if len(fr) != len(p):
            raise InputError(f"{len(p)} points with {len(fr)} frames")
        if len(p) == 0:
            return np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.int64)
        if fr.min() < 0 or fr.max() >= self.num_frames:
            raise InputError(f"frames must be in [0, {self.num_frames}), got {fr.min()}..{fr.max()}")
        beyond = np.full(len(p), np.inf) if outside_beyond is None else np.ascontiguousarray(outside_beyond,
                                                                                          np.float64)
        dist, closest, face = np.empty(len(p)), np.empty((len(p), 3)), np.empty(len(p), np.int32)
        arr = lambda a, dtype: wp.array(a, dtype=dtype, device="cpu", copy=False)  # noqa: E731
        wp.launch(self._kernel, dim=len(p), device="cpu",
                  inputs=[self._ids, self._verts_wp, self._faces_wp, self._corner_wp, self._fn_wp, self._en_wp,
                          self._vn_wp, self._low_wp, self._high_wp, self.verts.shape[1], len(self.faces),
                          self.num_edges,
                          arr(p, wp.vec3d), arr(fr, wp.int32), arr(beyond, wp.float64),
                          wp.float64(winding_from), arr(dist, wp.float64), arr(closest, wp.vec3d),
                          arr(face, wp.int32)])
        return dist, closest, face.astype(np.int64)
