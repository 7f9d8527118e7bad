"""Signed distance to a closed triangle mesh (the body), with the AABB tree built once.

The sign comes from angle-weighted pseudonormals (Baerentzen and Aanaes): at the closest point,
the normal of the face, edge or vertex that holds it; points on the side it points to are outside.
This is exact for closed, consistently oriented meshes such as the Anny body, and gives the same
answer as ``igl.signed_distance`` with the pseudonormal sign type without rebuilding its tree on
every call.

Where a posed body passes through itself the pseudonormal sign can be wrong; :meth:`BodySDF.inside` settles a
point's side by the generalised winding number instead (Warp's fast winding number, its hierarchy built once per
mesh; libigl's when Warp does not load).
"""

from __future__ import annotations

import igl
import numpy as np

from loosefit.errors import InputError
from loosefit.extras import warp_kernels


class BodySDF:
    """Signed distance to a closed, outward-oriented triangle mesh; negative inside.

    Args:
        verts: ``(V, 3)`` vertex positions, metres.
        faces: ``(F, 3)`` int triangles, counter-clockwise seen from outside.
    """

    def __init__(self, verts: np.ndarray, faces: np.ndarray):
        verts = np.ascontiguousarray(verts, dtype=np.float64)
        faces = np.ascontiguousarray(faces, dtype=np.int64)
        if verts.ndim != 2 or verts.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            raise InputError(f"BodySDF needs verts (V, 3) and faces (F, 3), got {verts.shape} and {faces.shape}")
        self.verts, self.faces = verts, faces
        self._tree = igl.AABB()
        self._tree.init(verts, faces)
        self.face_normals = igl.per_face_normals(verts, faces, np.array([0.0, 0.0, 1.0]))
        self._vertex_normals = igl.per_vertex_normals(
            verts, faces, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_ANGLE, self.face_normals
        )
        # Edge pseudonormal: sum of the normals of the (one or two) faces sharing the edge.
        corner_edges = np.stack([faces[:, [1, 2]], faces[:, [2, 0]], faces[:, [0, 1]]], 1).reshape(-1, 2)
        _, self._corner_edge, = np.unique(np.sort(corner_edges, 1), axis=0, return_inverse=True)
        self._corner_edge = self._corner_edge.reshape(-1, 3)  # edge opposite corner c of face f
        edge_normals = np.zeros((self._corner_edge.max() + 1, 3))
        np.add.at(edge_normals, self._corner_edge.reshape(-1), np.repeat(self.face_normals, 3, 0))
        self._edge_normals = edge_normals
        self._warp_mesh = None  # the winding number's hierarchy (:meth:`inside`), built when first needed

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance, closest surface point and its face.

        Args:
            points: ``(N, 3)`` query points, metres.

        Returns:
            ``dist (N,)`` float32 signed distances (negative inside), ``closest (N, 3)`` float32
            closest points on the mesh, ``face (N,)`` int64 ids of the faces holding them.
        """
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        if len(p) == 0:
            return np.zeros(0, np.float32), np.zeros((0, 3), np.float32), np.zeros(0, np.int64)
        sq, face, close = self._tree.squared_distance(self.verts, self.faces, p)
        tri = self.verts[self.faces[face]]
        bary = igl.barycentric_coordinates(close, tri[:, 0].copy(), tri[:, 1].copy(), tri[:, 2].copy())
        normal = self._pseudonormal(face, bary)
        side = np.einsum("ij,ij->i", p - close, normal)
        dist = np.sqrt(np.maximum(sq, 0.0)) * np.where(side < 0.0, -1.0, 1.0)
        return dist.astype(np.float32), close.astype(np.float32), face.astype(np.int64)

    def inside(self, points: np.ndarray, backend: str = "auto") -> np.ndarray:
        """``(N,)`` bool: the mesh's generalised winding number at ``points (N, 3)`` exceeds 1/2 (inside, also
        where the mesh passes through itself). ``backend``: ``"auto"`` (Warp when it loads, else libigl),
        ``"warp"`` or ``"igl"``. Warp's hierarchy is built on the first call and kept: about 1.8 ms for the
        1,229-vertex proxy, then about 0.02 ms a point, against libigl's 5.5 ms a call plus 0.01 ms a point."""
        if backend not in ("auto", "warp", "igl"):
            raise InputError(f"winding number backend must be 'auto', 'warp' or 'igl', got {backend!r}")
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        kernel = None if backend == "igl" else warp_kernels("loosefit.geometry._winding_warp", "winding_inside")
        if backend == "warp" and kernel is None:
            raise InputError("the Warp winding number needs warp (pip install warp-lang)")
        if len(p) == 0:
            return np.zeros(0, bool)
        if kernel is None:
            return igl.winding_number(self.verts, self.faces, p) > 0.5
        wp, winding_inside = kernel
        if self._warp_mesh is None:
            self._warp_mesh = wp.Mesh(points=wp.array(self.verts.astype(np.float32), dtype=wp.vec3, device="cpu"),
                                      indices=wp.array(self.faces.astype(np.int32).ravel(), dtype=wp.int32,
                                                       device="cpu"), support_winding_number=True)
        out = np.zeros(len(p), np.uint8)
        wp.launch(winding_inside, dim=len(p), device="cpu",
                  inputs=[self._warp_mesh.id, wp.array(p.astype(np.float32), dtype=wp.vec3, device="cpu"),
                          wp.array(out, dtype=wp.uint8, device="cpu", copy=False)])
        return out.astype(bool)

    def query(self, points: np.ndarray) -> np.ndarray:
        """``(N,)`` float32 signed distances of ``points (N, 3)`` to the mesh, metres, negative inside."""
        return self.closest(points)[0]

    def _pseudonormal(self, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """Normal of the feature (vertex, edge or face interior) holding each closest point."""
        eps = 1e-7
        zero = bary < eps
        count = zero.sum(1)
        normal = self.face_normals[face].copy()
        on_edge = count == 1  # one barycentric is zero: on the edge opposite that corner
        corner = np.argmax(zero, 1)
        normal[on_edge] = self._edge_normals[self._corner_edge[face[on_edge], corner[on_edge]]]
        on_vertex = count >= 2  # two zeros: at the corner with the remaining weight
        keep = np.argmax(bary, 1)
        normal[on_vertex] = self._vertex_normals[self.faces[face[on_vertex], keep[on_vertex]]]
        return normal


class PosedBodySDF(BodySDF):
    """:class:`BodySDF` of one frame of a body whose triangles never change (a posed body sequence): the
    edge map of its edge pseudonormals, a sort of every edge and most of the constructor's time (35 of
    ~70 ms a frame for the 1,229-vertex collision proxy on the shared 2-core machines), comes from ``like``,
    a frame of the same mesh. Distances are those of ``BodySDF(verts, like.faces)``, bit for bit.

    Args:
        verts: ``(V, 3)`` vertex positions of this frame, metres.
        like: the :class:`BodySDF` of another frame of the same triangles.
    """

    def __init__(self, verts: np.ndarray, like: BodySDF):
        verts = np.ascontiguousarray(verts, dtype=np.float64)
        if verts.shape != like.verts.shape:
            raise InputError(f"a posed frame needs vertices {like.verts.shape} like its first frame, got {verts.shape}")
        self.verts, self.faces, self._corner_edge = verts, like.faces, like._corner_edge
        self._tree = igl.AABB()
        self._tree.init(verts, self.faces)
        self.face_normals = igl.per_face_normals(verts, self.faces, np.array([0.0, 0.0, 1.0]))
        self._vertex_normals = igl.per_vertex_normals(
            verts, self.faces, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_ANGLE, self.face_normals)
        # the sum of the faces' normals at each edge, in the order np.add.at adds them (the same bits)
        index, n = self._corner_edge.reshape(-1), len(like._edge_normals)
        faces_normals = np.repeat(self.face_normals, 3, 0)
        self._edge_normals = np.stack([np.bincount(index, faces_normals[:, k], n) for k in range(3)], 1)
        self._warp_mesh = None


def posed_body_sdfs(verts: np.ndarray, faces: np.ndarray):
    """The :class:`BodySDF` of each frame of a posed body ``verts (T, Vb, 3)``, ``faces (F, 3)``, one at a time
    (a generator: the trees of a long motion are never all held): the first built in full, the others
    :class:`PosedBodySDF` like it."""
    first = None
    for frame in verts:
        if first is None:
            first = BodySDF(frame, faces)
            yield first
        else:
            yield PosedBodySDF(frame, first)
