"""Skinned meshes with baked joint animation as binary glTF (``.glb``), through ``pygltflib``.

Layout written, per :class:`~loosefit.io.skinned_mesh.SkinnedMesh` (``garment``, ``body``):

- a node ``<name>`` with the mesh (one indexed triangle primitive: ``POSITION`` the bind-pose mesh,
  ``JOINTS_0``/``WEIGHTS_0`` and, for 8 influences, ``JOINTS_1``/``WEIGHTS_1``; joints as unsigned
  bytes, or shorts past 256 joints) and its skin;
- a node ``<name>_rig`` (identity, the skin's ``skeleton``) holding the joint nodes in their hierarchy,
  each at its bind-pose local translation with no rotation; the skin's inverse bind matrices are
  ``translate(-b_j)`` (joint frames are world-aligned in the bind pose).

One animation (``extras.fps``) holds, per joint, a ``rotation`` channel and, where the local translation
changes over the motion (every free virtual bone, a body's root), a ``translation`` channel: one
``LINEAR`` keyframe per frame at ``t / fps`` seconds (quaternions kept in one hemisphere from frame to
frame so that blending between keyframes takes the short way). A glTF viewer then plays
``sum_k w_k  G_k(t) IBM_k  p`` = :meth:`SkinnedMesh.skin` at every keyframe.

glTF is Y-up: loosefit's Z-up data is rotated by ``C: (x, y, z) -> (x, z, -y)`` (points ``C p``,
rotations ``C R C^T``), which leaves the skinning equation unchanged up to that rotation.

Size: per vertex 12 bytes of position plus 20 (4 influences, byte joints) or 40 (8); per frame
``28 B`` per free bone (rotation and translation) and ``16 B`` per body joint, plus the root's
translation: a rig costs kilobytes per second where morph targets (:mod:`loosefit.io.gltf`) cost
``12 V`` bytes per frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib as gl  # one namespace: the names are the glTF schema's own
import torch

from loosefit.errors import InputError
from loosefit.geometry.rotations import matrix_to_quaternion
from loosefit.io.gltf import to_y_up
from loosefit.io.skinned_mesh import SkinnedMesh, common_timing
from loosefit.paths import atomic_path

#: glTF's axis change as a matrix: ``to_y_up(p) == Y_UP @ p``.
Y_UP = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
_COMPONENT = {np.float32: gl.FLOAT, np.uint32: gl.UNSIGNED_INT, np.uint16: gl.UNSIGNED_SHORT, np.uint8: gl.UNSIGNED_BYTE}
_WIDTH = {1: "SCALAR", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


class _Buffer:
    """One binary buffer: each array a buffer view (padded to 4 bytes) with one accessor."""

    def __init__(self, gltf: gl.GLTF2):
        self.gltf, self.chunks, self.size = gltf, [], 0

    def add(self, data: np.ndarray, width: int, target: int | None = None, bounds: bool = False) -> int:
        """An accessor over ``data`` as rows of ``width`` components (float32, uint8/16/32); its index."""
        data = np.ascontiguousarray(data)
        raw = data.tobytes()
        self.gltf.bufferViews.append(gl.BufferView(buffer=0, byteOffset=self.size, byteLength=len(raw), target=target))
        padded = raw + b"\0" * (-len(raw) % 4)
        self.chunks.append(padded)
        self.size += len(padded)
        rows = data.reshape(-1, width)
        accessor = gl.Accessor(bufferView=len(self.gltf.bufferViews) - 1, componentType=_COMPONENT[data.dtype.type],
                            count=len(rows), type=_WIDTH[width])
        if bounds:
            accessor.min, accessor.max = rows.min(0).tolist(), rows.max(0).tolist()
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1

    def blob(self) -> bytes:
        return b"".join(self.chunks)


def gltf_quaternions(rotations: np.ndarray) -> np.ndarray:
    """Z-up rotations ``(T, J, 3, 3)`` -> glTF ``(T, J, 4)`` float32 quaternions ``(x, y, z, w)`` of the
    Y-up rotations ``C R C^T``, each frame's in the hemisphere of the previous frame's."""
    R = Y_UP @ np.asarray(rotations, np.float64) @ Y_UP.T
    q = matrix_to_quaternion(torch.from_numpy(R)).numpy()[..., [1, 2, 3, 0]]  # (w, x, y, z) -> (x, y, z, w)
    flips = np.cumsum(np.concatenate([np.zeros_like(q[:1, :, 0]), (q[1:] * q[:-1]).sum(-1) < 0]), 0) % 2
    return np.where(flips[..., None] == 1, -q, q).astype(np.float32)


def write_skinned_glb(path: str | Path, meshes: list[SkinnedMesh]) -> None:
    """Write skinned meshes with their joint animation to a ``.glb`` (layout in the module docstring).

    All meshes must share the frame count and rate; each has at most 8 influences per vertex.
    """
    frames, fps = common_timing(meshes, path)
    for mesh in meshes:
        if mesh.influences > 8:
            raise InputError(f"mesh {mesh.name!r} has {mesh.influences} influences per vertex; glTF engines "
                             "take 4 or 8: limit them first (SkinnedMesh.limited)", path)
    gltf = gl.GLTF2(asset=gl.Asset(generator="loosefit"), scene=0, scenes=[gl.Scene(nodes=[])])
    cloth = gl.PbrMetallicRoughness(baseColorFactor=[0.8, 0.8, 0.8, 1.0], metallicFactor=0.0)
    gltf.materials.append(gl.Material(name="cloth", doubleSided=True, pbrMetallicRoughness=cloth))
    buffer = _Buffer(gltf)
    times = np.arange(frames, dtype=np.float32) / np.float32(fps)
    animation = gl.Animation(name="loosefit", extras={"fps": float(fps)})
    keyframes = buffer.add(times, 1, bounds=True)
    for mesh in meshes:
        _add_skinned_mesh(gltf, buffer, animation, keyframes, mesh)
    gltf.animations.append(animation)
    blob = buffer.blob()
    gltf.buffers.append(gl.Buffer(byteLength=len(blob)))
    gltf.set_binary_blob(blob)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(b"".join(gltf.save_to_bytes()))


def _add_skinned_mesh(gltf: gl.GLTF2, buffer: _Buffer, animation: gl.Animation, keyframes: int, mesh: SkinnedMesh) -> None:
    """The mesh node, its rig node with the joint nodes, its skin and its animation channels (``keyframes``:
    the accessor of the keyframe times)."""
    V, J = len(mesh.rest_verts), mesh.num_joints
    faces = mesh.faces.astype(np.uint32)
    position = to_y_up(mesh.rest_verts).astype(np.float32)
    attributes = gl.Attributes(POSITION=buffer.add(position, 3, gl.ARRAY_BUFFER, bounds=True))
    sets = -(-mesh.influences // 4)
    idx = np.zeros((V, 4 * sets), np.uint8 if J <= 256 else np.uint16)
    val = np.zeros((V, 4 * sets), np.float32)
    idx[:, : mesh.influences], val[:, : mesh.influences] = mesh.weight_indices, mesh.weight_values
    for s in range(sets):
        setattr(attributes, f"JOINTS_{s}", buffer.add(idx[:, 4 * s : 4 * s + 4], 4, gl.ARRAY_BUFFER))
        setattr(attributes, f"WEIGHTS_{s}", buffer.add(val[:, 4 * s : 4 * s + 4], 4, gl.ARRAY_BUFFER))
    primitive = gl.Primitive(attributes=attributes, indices=buffer.add(faces.ravel(), 1, gl.ELEMENT_ARRAY_BUFFER), material=0)
    gltf.meshes.append(gl.Mesh(name=mesh.name, primitives=[primitive]))

    rig = len(gltf.nodes)
    gltf.nodes.append(gl.Node(name=f"{mesh.name}_rig", children=[]))
    first = len(gltf.nodes)
    bind_local = to_y_up(mesh.bind_local())
    for j, name in enumerate(mesh.joint_names):
        gltf.nodes.append(gl.Node(name=name, translation=bind_local[j].tolist(), children=[]))
        parent = rig if mesh.parents[j] < 0 else first + int(mesh.parents[j])
        gltf.nodes[parent].children.append(first + j)
    for node in gltf.nodes[first:]:
        node.children = node.children or None
    inverse_bind = np.tile(np.eye(4, dtype=np.float32), (J, 1, 1))
    inverse_bind[:, :3, 3] = -to_y_up(mesh.bind_positions.astype(np.float64))
    ibm = buffer.add(inverse_bind.transpose(0, 2, 1).reshape(J, 16), 16)  # glTF matrices are column-major
    gltf.skins.append(gl.Skin(name=mesh.name, inverseBindMatrices=ibm, skeleton=rig, joints=list(range(first, first + J))))
    gltf.nodes.append(gl.Node(name=mesh.name, mesh=len(gltf.meshes) - 1, skin=len(gltf.skins) - 1))
    gltf.scenes[0].nodes += [len(gltf.nodes) - 1, rig]

    rotations = gltf_quaternions(mesh.rotations)  # (T, J, 4)
    translations = to_y_up(mesh.translations).astype(np.float32)  # (T, J, 3)
    moving = np.abs(translations - translations[:1]).max(0).max(-1) > 0
    for j in range(J):
        channels = [("rotation", rotations[:, j], 4)]
        if moving[j]:
            channels.append(("translation", translations[:, j], 3))
        else:
            gltf.nodes[first + j].translation = translations[0, j].tolist()
        for path, values, width in channels:
            output = buffer.add(values, width)
            animation.samplers.append(gl.AnimationSampler(input=keyframes, output=output, interpolation="LINEAR"))
            target = gl.AnimationChannelTarget(node=first + j, path=path)
            animation.channels.append(gl.AnimationChannel(sampler=len(animation.samplers) - 1, target=target))
