"""Mesh sequences as binary glTF (``.glb``) morph-target animations, through ``pygltflib``.

Layout written: one node and mesh per animated mesh (``garment``, and ``body`` when the sequence has
one). The mesh's base ``POSITION`` is a rest mesh (the first frame unless given); frame ``t`` is morph
target ``t`` (``POSITION`` deltas from the base, target names ``frame_00000`` ... in
``mesh.extras.targetNames``). One animation drives the ``weights`` of every node with one keyframe
per frame at ``t / fps`` seconds whose weights are one-hot (target ``t`` at 1), with ``STEP``
interpolation (the frames as they are) or ``LINEAR`` (positions blend between frames), so any glTF
viewer plays the sequence. The frame rate is also kept in ``animation.extras.fps``.

glTF is Y-up: loosefit's Z-up ``(x, y, z)`` is stored as ``(x, z, -y)`` and converted back on read.
Positions go through ``base + (frame - base)`` in float32, so they round-trip to within one float32
rounding step (~1e-7 m for a garment near the origin), not bit-exactly.

Size: the morph targets hold every frame, ``T * V * 12`` bytes (a 3,000-vertex garment: 36 kB per
frame, 1.1 MB per second at 30 fps), and the dense one-hot weights ``T * T * 4`` bytes (30 s: 3.2 MB,
3 min: 117 MB beside 194 MB of targets). Viewers keep all targets in memory: glTF suits clips of
seconds to a minute; for long sequences prefer USD, Alembic or PC2.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pygltflib import (
    ARRAY_BUFFER,
    ELEMENT_ARRAY_BUFFER,
    FLOAT,
    GLTF2,
    UNSIGNED_INT,
    Accessor,
    Animation,
    AnimationChannel,
    AnimationChannelTarget,
    AnimationSampler,
    Asset,
    Attributes,
    Buffer,
    BufferView,
    Material,
    Mesh,
    Node,
    PbrMetallicRoughness,
    Primitive,
    Scene,
)

from loosefit.errors import InputError
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.paths import atomic_path

INTERPOLATIONS = ("STEP", "LINEAR")
_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_DTYPES = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}


def to_y_up(verts: np.ndarray) -> np.ndarray:
    """Z-up ``(..., 3)`` points to glTF's Y-up: ``(x, y, z) -> (x, z, -y)`` (exact)."""
    return np.stack([verts[..., 0], verts[..., 2], -verts[..., 1]], axis=-1)


def from_y_up(verts: np.ndarray) -> np.ndarray:
    """glTF Y-up ``(..., 3)`` points back to Z-up: ``(x, y, z) -> (x, -z, y)`` (exact)."""
    return np.stack([verts[..., 0], -verts[..., 2], verts[..., 1]], axis=-1)


class _Builder:
    """Accumulates one binary buffer, its buffer views and accessors for a glTF document."""

    def __init__(self, gltf: GLTF2):
        self.gltf = gltf
        self.chunks: list[bytes] = []
        self.size = 0

    def view(self, data: np.ndarray, target: int | None = None) -> int:
        """Append ``data`` (4-byte components, so views stay aligned) as a new buffer view; its index."""
        raw = np.ascontiguousarray(data).tobytes()
        self.gltf.bufferViews.append(BufferView(buffer=0, byteOffset=self.size, byteLength=len(raw), target=target))
        self.chunks.append(raw)
        self.size += len(raw)
        return len(self.gltf.bufferViews) - 1

    def accessor(self, view: int, data: np.ndarray, kind: str, offset: int = 0, bounds: bool = False) -> int:
        """An accessor over ``data`` (rows of ``kind``) at byte ``offset`` in ``view``; min/max when ``bounds``."""
        rows = data.reshape(-1, _COMPONENTS[kind])
        accessor = Accessor(
            bufferView=view,
            byteOffset=offset,
            componentType=FLOAT if data.dtype == np.float32 else UNSIGNED_INT,
            count=len(rows),
            type=kind,
        )
        if bounds:  # float32 values are exact in JSON doubles
            accessor.min, accessor.max = rows.min(0).tolist(), rows.max(0).tolist()
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1

    def blob(self) -> bytes:
        return b"".join(self.chunks)


def write_glb(path: str | Path, seq: MeshSequence, rest: np.ndarray | None = None, interpolation: str = "STEP") -> None:
    """Write ``seq`` (garment, and body if ``seq.extra`` has ``body_verts``/``body_faces``) as a ``.glb`` animation.

    Args:
        path: output ``.glb``.
        seq: the sequence, ``verts (T, V, 3)`` Z-up metres.
        rest: ``(V, 3)`` base mesh of the garment (the first frame when ``None``); the body always uses its first frame.
        interpolation: ``"STEP"`` or ``"LINEAR"`` between keyframes.
    """
    if interpolation not in INTERPOLATIONS:
        raise InputError(f"interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}", path)
    if rest is not None and (np.shape(rest) != seq.verts.shape[1:] or not np.isfinite(rest).all()):
        raise InputError(f"rest mesh must be finite with the garment's shape {seq.verts.shape[1:]}, got {np.shape(rest)}", path)
    num_frames = len(seq.verts)
    gltf = GLTF2(asset=Asset(generator="loosefit"), scene=0, scenes=[Scene(nodes=[])])
    cloth = PbrMetallicRoughness(baseColorFactor=[0.8, 0.8, 0.8, 1.0], metallicFactor=0.0)
    gltf.materials.append(Material(name="cloth", doubleSided=True, pbrMetallicRoughness=cloth))  # cloth shows both sides
    builder = _Builder(gltf)
    times = np.arange(num_frames, dtype=np.float32) / np.float32(seq.fps)
    times_accessor = builder.accessor(builder.view(times), times, "SCALAR", bounds=True)
    weights = np.eye(num_frames, dtype=np.float32)  # keyframe t selects target t
    weights_view = builder.view(weights)
    animation = Animation(name="loosefit", extras={"fps": float(seq.fps)})

    meshes = [("garment", seq.verts, seq.faces, seq.verts[0] if rest is None else rest)]
    if "body_verts" in seq.extra:
        body_verts = np.asarray(seq.extra["body_verts"], np.float32)
        meshes.append(("body", body_verts, seq.extra["body_faces"], body_verts[0]))
    for name, verts, faces, base in meshes:
        node = _add_morph_mesh(gltf, builder, name, verts, faces, base)
        output = builder.accessor(weights_view, weights, "SCALAR")
        animation.samplers.append(AnimationSampler(input=times_accessor, output=output, interpolation=interpolation))
        target = AnimationChannelTarget(node=node, path="weights")
        animation.channels.append(AnimationChannel(sampler=len(animation.samplers) - 1, target=target))
    gltf.animations.append(animation)

    blob = builder.blob()
    gltf.buffers.append(Buffer(byteLength=len(blob)))
    gltf.set_binary_blob(blob)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(b"".join(gltf.save_to_bytes()))


def _add_morph_mesh(gltf: GLTF2, builder: _Builder, name: str, verts: np.ndarray, faces: np.ndarray, base: np.ndarray) -> int:
    """Add a mesh whose morph target ``t`` moves ``base (V, 3)`` to ``verts[t]``, and its node; the node index."""
    base_y = to_y_up(np.asarray(base, np.float32))
    deltas = to_y_up(np.asarray(verts, np.float32)) - base_y  # (T, V, 3)
    faces = np.asarray(faces, np.uint32)
    indices = builder.accessor(builder.view(faces, ELEMENT_ARRAY_BUFFER), faces, "SCALAR")
    position = builder.accessor(builder.view(base_y, ARRAY_BUFFER), base_y, "VEC3", bounds=True)
    targets_view = builder.view(deltas, ARRAY_BUFFER)
    targets = [
        Attributes(POSITION=builder.accessor(targets_view, delta, "VEC3", offset=t * delta.nbytes, bounds=True))
        for t, delta in enumerate(deltas)
    ]
    primitive = Primitive(attributes=Attributes(POSITION=position), indices=indices, material=0, targets=targets)
    weights = [0.0] * len(deltas)
    weights[0] = 1.0  # without animation the mesh shows the first frame
    names = [f"frame_{t:05d}" for t in range(len(deltas))]
    gltf.meshes.append(Mesh(name=name, primitives=[primitive], weights=weights, extras={"targetNames": names}))
    gltf.nodes.append(Node(name=name, mesh=len(gltf.meshes) - 1))
    gltf.scenes[0].nodes.append(len(gltf.nodes) - 1)
    return len(gltf.nodes) - 1


def read_glb(path: str | Path) -> MeshSequence:
    """Read a ``.glb`` morph-target animation back into a Z-up :class:`MeshSequence`.

    The node named ``garment`` (else the first node with a mesh) gives ``verts (T, V, 3)``: one frame
    per keyframe of the animation channel on its ``weights`` (base + weighted targets), or one frame
    from the mesh's default weights when nothing animates it. ``fps`` comes from ``animation.extras.fps``,
    else from the keyframe spacing. A ``body`` node beside ``garment`` goes to ``extra``. Meshes must
    be one indexed triangle primitive; node transforms are not applied (a node carrying one is refused).
    """
    path = Path(path)
    try:
        gltf = GLTF2.load_binary(path)
    except Exception as e:  # pygltflib raises bare IOError/KeyError/struct.error on damaged files
        raise InputError(f"cannot read glTF binary: {e}", path) from None
    if gltf is None or gltf.binary_blob() is None:
        raise InputError("not a binary glTF file with an embedded buffer", path)
    mesh_nodes = [i for i, node in enumerate(gltf.nodes) if node.mesh is not None]
    if not mesh_nodes:
        raise InputError("no node with a mesh", path)
    named = {gltf.nodes[i].name: i for i in reversed(mesh_nodes)}  # the first node of each name wins
    verts, faces, fps = _read_node(gltf, named.get("garment", mesh_nodes[0]), path)
    extra = {}
    if "garment" in named and "body" in named:
        extra["body_verts"], extra["body_faces"], _ = _read_node(gltf, named["body"], path)
    return MeshSequence(verts, faces, fps, extra)


def _read_node(gltf: GLTF2, node_index: int, path: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """``(verts (T, V, 3) float32 Z-up, faces (F, 3) int64, fps)`` of a node's animated morph-target mesh."""
    node = gltf.nodes[node_index]
    if _has_transform(node):
        raise InputError(f"node {node.name!r} has a transform; only untransformed meshes are read", path)
    mesh = gltf.meshes[node.mesh]
    if len(mesh.primitives) != 1 or mesh.primitives[0].mode not in (None, 4) or mesh.primitives[0].indices is None:
        raise InputError(f"mesh {mesh.name!r} must be one indexed triangle primitive", path)
    primitive = mesh.primitives[0]
    base = _read_accessor(gltf, primitive.attributes.POSITION, path).astype(np.float32)
    faces = _read_accessor(gltf, primitive.indices, path).astype(np.int64).reshape(-1, 3)
    if faces.size and faces.max() >= len(base):
        raise InputError(f"mesh {mesh.name!r} has face indices outside [0, {len(base)})", path)
    # targets are Attributes when built in memory, plain dicts when loaded from JSON
    deltas = [_read_accessor(gltf, t["POSITION"] if isinstance(t, dict) else t.POSITION, path)
              for t in primitive.targets or []]

    weights, fps = np.asarray([mesh.weights or [0.0] * len(deltas)], np.float32), 30.0  # no animation: one frame
    for animation in gltf.animations:
        for channel in animation.channels:
            if channel.target.node == node_index and channel.target.path == "weights":
                sampler = animation.samplers[channel.sampler]
                if sampler.interpolation not in INTERPOLATIONS:
                    raise InputError(f"{sampler.interpolation} weight animation is not supported", path)
                times = _read_accessor(gltf, sampler.input, path).ravel()
                weights = _read_accessor(gltf, sampler.output, path).reshape(len(times), -1)
                fps = float((animation.extras or {}).get("fps") or _keyframe_rate(times))
    if weights.shape[1] != len(deltas):
        raise InputError(f"mesh {mesh.name!r}: {weights.shape[1]} weights per keyframe for {len(deltas)} morph targets", path)
    verts = np.repeat(base[None], len(weights), axis=0)
    for frame, row in enumerate(weights):
        for target in np.flatnonzero(row):  # skip zeros: a one-hot row costs one addition
            verts[frame] += row[target] * deltas[target]
    return from_y_up(verts), faces, fps


def _has_transform(node: Node) -> bool:
    """Whether a glTF node moves its mesh (a non-identity matrix, translation, rotation or scale)."""
    identity = [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]
    return (node.matrix not in (None, identity) or node.translation not in (None, [0, 0, 0])
            or node.rotation not in (None, [0, 0, 0, 1]) or node.scale not in (None, [1, 1, 1]))


def _keyframe_rate(times: np.ndarray) -> float:
    """Keyframes per second of evenly spaced ``times`` (30 for a single keyframe), to 6 decimals."""
    if len(times) < 2 or times[-1] <= times[0]:
        return 30.0
    return float(np.round((len(times) - 1) / (float(times[-1]) - float(times[0])), 6))


def _read_accessor(gltf: GLTF2, index: int, path: Path) -> np.ndarray:
    """The data of accessor ``index`` as ``(count, components)`` (byte strides honoured; sparse refused)."""
    accessor = gltf.accessors[index]
    if accessor.sparse is not None or accessor.bufferView is None:
        raise InputError(f"accessor {index} is sparse or has no buffer view; not supported", path)
    if accessor.componentType not in _DTYPES or (accessor.normalized and accessor.componentType != 5126):
        raise InputError(f"accessor {index} has unsupported component type {accessor.componentType}", path)
    view = gltf.bufferViews[accessor.bufferView]
    if view.buffer != 0:
        raise InputError(f"accessor {index} reads buffer {view.buffer}; only the embedded buffer is supported", path)
    dtype = np.dtype(_DTYPES[accessor.componentType]).newbyteorder("<")
    components = _COMPONENTS[accessor.type]
    stride = view.byteStride or dtype.itemsize * components
    start = (view.byteOffset or 0) + (accessor.byteOffset or 0)
    blob = gltf.binary_blob()
    end = start + stride * (accessor.count - 1) + dtype.itemsize * components if accessor.count else start
    if end > (view.byteOffset or 0) + view.byteLength or end > len(blob):
        raise InputError(f"accessor {index} reads past the end of its buffer view", path)
    data = np.ndarray((accessor.count, components), dtype, buffer=blob, offset=start, strides=(stride, dtype.itemsize))
    return data.astype(dtype.newbyteorder("="))
