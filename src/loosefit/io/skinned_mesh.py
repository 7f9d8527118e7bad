"""A mesh skinned by a joint hierarchy with its joint animation baked per frame: what the engine-ready
exports (:mod:`loosefit.io.skinned_gltf`, :mod:`loosefit.io.skinned_usd`) write.

Conventions (those of :mod:`loosefit.geometry.lbs`, Z-up metres): in the bind pose every joint frame is
aligned with the world axes and sits at its bind position ``b_j``; the bind-pose mesh is ``rest_verts``.
Frame ``t`` gives each joint a local transform ``[R_j(t) | t_j(t)]`` relative to its parent's frame (a
root's is its world transform), so the world transform is ``G_j = G_parent [R_j | t_j]`` and linear blend
skinning with sparse weights ``(k_i, w_i)`` gives::

    v_i(t) = sum_k w_ik  G_{k_ik}(t) [I | -b_{k_ik}] p_i                    (linear blend skinning)

Free virtual bones (VirtualBones Eq. 1, ``v = sum_j W_ij (R_j p + T_j)``) are roots with ``b_j`` their rest
centroid ``c_j``, ``R_j(t)`` their rotation and ``t_j(t) = R_j c_j + T_j``; a body is its rig, ``t_j`` of a
non-root joint being its rest offset from its parent.

Engines take at most 4 or 8 influences per vertex: :func:`top_influences` keeps each vertex's largest
weights and renormalises them (:meth:`SkinnedMesh.limited`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from loosefit.errors import InputError


def top_influences(indices: np.ndarray, values: np.ndarray, limit: int) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's ``limit`` largest weights, renormalised to sum to 1.

    Args:
        indices: ``(V, K)`` int joint indices; values: ``(V, K)`` weights >= 0 (any order, zeros allowed).
        limit: influences kept per vertex (>= 1).

    Returns:
        ``(V, limit)`` int64 indices and float32 weights sorted decreasing; slots without weight hold
        joint 0 and weight 0 (``K < limit`` pads).
    """
    if limit < 1:
        raise InputError(f"influences per vertex must be at least 1, got {limit}")
    indices, values = np.asarray(indices, np.int64), np.asarray(values, np.float64)
    order = np.argsort(-values, axis=1, kind="stable")[:, :limit]
    idx, val = np.take_along_axis(indices, order, 1), np.take_along_axis(values, order, 1)
    total = val.sum(1, keepdims=True)
    if (total <= 0).any():
        raise InputError(f"vertex {int(np.argmax(total[:, 0] <= 0))} has no skinning weight")
    val = val / total
    pad = limit - val.shape[1]
    if pad > 0:
        idx = np.pad(idx, ((0, 0), (0, pad)))
        val = np.pad(val, ((0, 0), (0, pad)))
    return np.where(val > 0, idx, 0), val.astype(np.float32)


def dense_to_sparse(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dense ``(V, J)`` weights -> ``(V, K)`` indices and values, ``K`` the most non-zero weights of a vertex."""
    weights = np.asarray(weights)
    K = max(int((weights > 0).sum(1).max()), 1)
    order = np.argsort(-weights, axis=1, kind="stable")[:, :K]
    values = np.take_along_axis(weights, order, 1)
    return np.where(values > 0, order, 0), values.astype(np.float32)


@dataclass
class SkinnedMesh:
    """A skinned mesh and its baked joint animation (see the module docstring).

    Attributes:
        name: the mesh's name in the exported file (``garment``, ``body``).
        rest_verts: ``(V, 3)`` float32 bind-pose mesh, metres, Z up.
        faces: ``(F, 3)`` int64 triangles.
        joint_names: ``J`` joint names.
        parents: ``(J,)`` int64 parent of each joint, -1 for a root; parents come before their children.
        bind_positions: ``(J, 3)`` float32 joint positions in the bind pose (frames world-aligned there).
        rotations: ``(T, J, 3, 3)`` float64 local joint rotations.
        translations: ``(T, J, 3)`` float64 local joint translations, metres.
        weight_indices: ``(V, K)`` int64 joints of each vertex's influences.
        weight_values: ``(V, K)`` float32 influence weights, rows summing to 1.
        fps: frames per second of the animation.
    """

    name: str
    rest_verts: np.ndarray
    faces: np.ndarray
    joint_names: list[str]
    parents: np.ndarray
    bind_positions: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    weight_indices: np.ndarray
    weight_values: np.ndarray
    fps: float = 30.0

    def __post_init__(self):
        self.rest_verts = np.asarray(self.rest_verts, np.float32)
        self.faces = np.asarray(self.faces, np.int64)
        self.joint_names = [str(n) for n in self.joint_names]
        self.parents = np.asarray(self.parents, np.int64)
        self.bind_positions = np.asarray(self.bind_positions, np.float32)
        self.rotations = np.asarray(self.rotations, np.float64)
        self.translations = np.asarray(self.translations, np.float64)
        self.weight_indices = np.asarray(self.weight_indices, np.int64)
        self.weight_values = np.asarray(self.weight_values, np.float32)
        V, J = len(self.rest_verts), len(self.joint_names)
        T = len(self.rotations)
        problems = []
        if self.rest_verts.ndim != 2 or self.rest_verts.shape[1] != 3 or not np.isfinite(self.rest_verts).all():
            problems.append(f"rest mesh must be finite (V, 3), got {self.rest_verts.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or self.faces.min() < 0 or self.faces.max() >= V:
            problems.append(f"faces must be (F, 3) indices into {V} vertices")
        if self.parents.shape != (J,) or self.bind_positions.shape != (J, 3):
            problems.append(f"{J} joints need parents ({J},) and bind positions ({J}, 3), got "
                            f"{self.parents.shape} and {self.bind_positions.shape}")
        elif any(not -1 <= p < j for j, p in enumerate(self.parents)):
            problems.append("joint parents must come before their children (-1 for a root)")
        if T == 0 or self.rotations.shape != (T, J, 3, 3) or self.translations.shape != (T, J, 3):
            problems.append(f"joint animation must be rotations (T, {J}, 3, 3) and translations (T, {J}, 3) "
                            f"with T > 0, got {self.rotations.shape} and {self.translations.shape}")
        elif not (np.isfinite(self.rotations).all() and np.isfinite(self.translations).all()):
            problems.append("joint animation is not finite (NaN or inf)")
        if self.weight_indices.shape != self.weight_values.shape or self.weight_indices.shape[:1] != (V,):
            problems.append(f"weights must be (V, K) index and value arrays for {V} vertices, got "
                            f"{self.weight_indices.shape} and {self.weight_values.shape}")
        elif self.weight_indices.min() < 0 or self.weight_indices.max() >= J:
            problems.append(f"weight indices outside [0, {J})")
        if not self.fps > 0:
            problems.append(f"fps must be positive, got {self.fps}")
        if problems:
            raise InputError(f"skinned mesh {self.name!r}: " + "; ".join(problems))

    @property
    def num_frames(self) -> int:
        return len(self.rotations)

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def influences(self) -> int:
        return self.weight_indices.shape[1]

    def limited(self, influences: int) -> "SkinnedMesh":
        """The same mesh with each vertex's ``influences`` largest weights, renormalised (:func:`top_influences`)."""
        idx, val = top_influences(self.weight_indices, self.weight_values, influences)
        return replace(self, weight_indices=idx, weight_values=val)

    def bind_local(self) -> np.ndarray:
        """``(J, 3)`` float64 bind-pose local translations: a root's bind position, else its offset from the parent."""
        bind = self.bind_positions.astype(np.float64)
        parent = np.where(self.parents[:, None] >= 0, bind[np.maximum(self.parents, 0)], 0.0)
        return bind - parent

    def world_transforms(self, frames=slice(None)) -> np.ndarray:
        """``(T', J, 4, 4)`` float64 world transforms ``G_j(t)`` of the joints at ``frames`` (a slice or indices)."""
        rotations, translations = self.rotations[frames], self.translations[frames]
        local = np.zeros(rotations.shape[:2] + (4, 4))
        local[..., :3, :3], local[..., :3, 3], local[..., 3, 3] = rotations, translations, 1.0
        world = np.empty_like(local)
        for j, p in enumerate(self.parents):
            world[:, j] = local[:, j] if p < 0 else world[:, p] @ local[:, j]
        return world

    def skinning_transforms(self, frames=slice(None)) -> np.ndarray:
        """``(T', J, 3, 4)`` float64 ``G_j(t) [I | -b_j]`` of ``frames`` (a slice or indices): bind-pose points to frame ``t``."""
        G = self.world_transforms(frames)[..., :3, :]
        out = G.copy()
        out[..., 3] = G[..., 3] - (G[..., :3, :3] @ self.bind_positions.astype(np.float64)[:, :, None])[..., 0]
        return out

    def dense_weights(self) -> np.ndarray:
        """``(V, J)`` float64 skinning weights."""
        W = np.zeros((len(self.rest_verts), self.num_joints))
        np.add.at(W, (np.arange(len(W))[:, None], self.weight_indices), self.weight_values.astype(np.float64))
        return W

    def skin(self, frames=slice(None), weights: np.ndarray | None = None) -> np.ndarray:
        """``(T', V, 3)`` float64 skinned vertices of ``frames`` (a slice or indices; default all), by linear
        blend skinning (module docstring): the blended transforms are one dense product ``W A``.

        ``weights``: dense ``(V, J)`` weights used instead of the mesh's (the difference of two weight sets
        gives the difference of their skinned meshes). Memory: ``T' * V * 96`` bytes; skin long motions in slices.
        """
        A = self.skinning_transforms(frames)  # (T', J, 3, 4)
        T, J = A.shape[:2]
        W = self.dense_weights() if weights is None else np.asarray(weights, np.float64)
        blend = (W @ A.transpose(1, 0, 2, 3).reshape(J, -1)).reshape(-1, T, 3, 4)  # (V, T', 3, 4)
        p = self.rest_verts.astype(np.float64)[:, None, None]  # (V, 1, 1, 3)
        skinned = blend[..., 0] * p[..., 0] + blend[..., 1] * p[..., 1] + blend[..., 2] * p[..., 2] + blend[..., 3]
        return skinned.transpose(1, 0, 2)


def common_timing(meshes: list["SkinnedMesh"], path) -> tuple[int, float]:
    """``(frames, fps)`` shared by all ``meshes``; an :class:`InputError` naming ``path`` when they differ or none is given."""
    if not meshes:
        raise InputError("no mesh to write", path)
    frames, fps = meshes[0].num_frames, meshes[0].fps
    for mesh in meshes:
        if mesh.num_frames != frames or mesh.fps != fps:
            raise InputError(f"mesh {mesh.name!r} has {mesh.num_frames} frames at {mesh.fps:g} fps, "
                             f"{meshes[0].name!r} {frames} at {fps:g}", path)
    return frames, fps
