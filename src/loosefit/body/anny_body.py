"""The default body: Anny (Apache-2.0 code, CC0 MakeHuman data), rig ``cmu_mb`` (31 CMU-named joints).

Anny's own frame is Z up, facing -Y, left on +X, root at the origin. loosefit shifts it so that the
rest-pose body stands with its soles on ``z = 0`` and its root joint above the origin; the low
resolution collision proxy shares that frame exactly.
"""

from __future__ import annotations

import dataclasses
import fcntl
import functools
import logging
from dataclasses import dataclass

import numpy as np
import torch

from loosefit.body.base import BodyModel
from loosefit.errors import InputError
from loosefit.paths import anny_cache_dir

log = logging.getLogger(__name__)

#: Anny topologies: the full MakeHuman mesh (13,718 vertices) and a decimated one (1,229 vertices).
TOPOLOGIES = {"full": "anny", "low": "notoes_collapse10pc"}


@dataclass(frozen=True)
class AnnyShape:
    """Anny's six phenotype values, each in ``[0, 1]`` (0.5 is the average adult)."""

    gender: float = 0.5
    age: float = 0.5
    muscle: float = 0.5
    weight: float = 0.5
    height: float = 0.5
    proportions: float = 0.5

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and 0.0 <= float(v) <= 1.0):
                raise InputError(f"Anny shape value {f.name}={v!r} must be a number in [0, 1]")

    @classmethod
    def names(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls)]

    @classmethod
    def parse(cls, text: str | None) -> "AnnyShape":
        """Parse ``"gender=0.8,weight=0.3"`` (unnamed values keep their default)."""
        if not text:
            return cls()
        values = {}
        for item in text.split(","):
            key, sep, val = item.partition("=")
            key = key.strip()
            if not sep or key not in cls.names():
                raise InputError(f"bad shape item {item!r}: expected NAME=VALUE with NAME in {cls.names()}")
            if key in values:
                raise InputError(f"bad shape {text!r}: {key} is given twice (each shape value once)")
            try:
                values[key] = float(val)
            except ValueError:
                raise InputError(f"bad shape value {item!r}: not a number") from None
        return cls(**values)

    @classmethod
    def from_array(cls, values) -> "AnnyShape":
        """From a ``(6,)`` array in :meth:`names` order."""
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        if values.shape != (6,):
            raise InputError(f"Anny shape needs 6 values {cls.names()}, got {values.shape[0]}")
        # Round so that a float32 round trip gives back the same (hashable, cache-key) shape.
        return cls(*(round(float(v), 6) for v in values))

    def to_array(self) -> np.ndarray:
        """``(6,)`` float32 in :meth:`names` order."""
        return np.array(dataclasses.astuple(self), dtype=np.float32)


@functools.lru_cache(maxsize=4)
def load_anny(rig: str = "cmu_mb", topology: str = "anny"):
    """Anny's torch model (cached per process). The first call ever builds Anny's cache under
    :func:`loosefit.paths.anny_cache_dir` (40-70 s, ~790 MB); later calls take ~0.3 s. Processes loading at
    the same time (parallel tests, several plan workers on a fresh machine) take turns on the cache's lock
    file, so that none reads a cache another is still writing."""
    import anny
    import anny.paths

    cache = anny_cache_dir()
    anny.paths.set_anny_cache_path(cache)
    log.info("loading Anny rig=%s topology=%s (cache %s)", rig, topology, cache)
    with open(cache / ".loosefit-lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        model = anny.Anny(rig=rig, topology=topology)
    if model.reference_bone_orientations is not None:
        raise RuntimeError(f"Anny rig {rig!r} has reference orientations; loosefit expects world-aligned joints")
    return model.eval()


@functools.lru_cache(maxsize=4)
def _anny_topology(rig: str, topology: str) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, np.ndarray]:
    """Joint names, parents ``(J,)`` int64, triangles ``(F, 3)`` int64 and skinning weights ``(V, J)`` float32 of an
    Anny rig and topology, read once per process (Anny lists its faces in Python: about 0.1 s a read; a copy
    takes a millisecond)."""
    model = load_anny(rig, topology)
    parents = np.asarray(model.bone_parents, dtype=np.int64)
    faces = model.get_triangular_faces().numpy().astype(np.int64)
    dense = torch.zeros(model.vertex_bone_indices.shape[0], model.bone_count, dtype=torch.float64)
    dense.scatter_add_(1, model.vertex_bone_indices.long(), model.vertex_bone_weights.double())
    weights = (dense / dense.sum(1, keepdim=True)).numpy().astype(np.float32)
    return tuple(model.bone_labels), parents, faces, weights


def anny_rest_pose(model, shape: AnnyShape) -> tuple[np.ndarray, np.ndarray]:
    """Anny's rest vertices ``(V, 3)`` and joint heads ``(J, 3)`` in Anny's own frame, float64."""
    J = model.bone_count
    pose = torch.eye(4, dtype=model.dtype).expand(1, J, 4, 4).clone()
    phen = {k: float(v) for k, v in dataclasses.asdict(shape).items()}
    with torch.no_grad():
        out = model(pose_parameters=pose, phenotype_kwargs=phen)
    return out["rest_vertices"][0].numpy(), out["rest_bone_heads"][0].numpy()


class AnnyBody(BodyModel):
    """Anny body of a given shape.

    Args:
        shape: phenotype values; the default is the average adult.
        resolution: ``"full"`` (13,718 vertices) or ``"low"`` (1,229 vertices, the collision proxy).
        rig: Anny rig; ``"cmu_mb"`` (31 joints named as in the CMU mocap database) by default.
    """

    def __init__(self, shape: AnnyShape | None = None, resolution: str = "full", rig: str = "cmu_mb"):
        if resolution not in TOPOLOGIES:
            raise InputError(f"Anny resolution must be one of {list(TOPOLOGIES)}, got {resolution!r}")
        self.shape = shape or AnnyShape()
        self.resolution = resolution
        self.rig = rig
        self.name = f"anny-{resolution}"
        joint_names, parents, faces, weights = _anny_topology(rig, TOPOLOGIES[resolution])
        self.joint_names = list(joint_names)
        self.parents, self.faces, self._weights = parents.copy(), faces.copy(), weights.copy()  # each body its own
        self._rest: dict[AnnyShape, tuple[np.ndarray, np.ndarray]] = {}
        self._proxy: AnnyBody | None = None

    def _resolve(self, shape) -> AnnyShape:
        if shape is None:
            return self.shape
        if isinstance(shape, AnnyShape):
            return shape
        if isinstance(shape, str):
            return AnnyShape.parse(shape)
        return AnnyShape.from_array(shape)

    def _rest_geometry(self, shape) -> tuple[np.ndarray, np.ndarray]:
        shape = self._resolve(shape)
        if shape not in self._rest:
            verts, joints = anny_rest_pose(load_anny(self.rig, TOPOLOGIES[self.resolution]), shape)
            offset = floor_offset(self.rig, shape)
            self._rest[shape] = ((verts + offset).astype(np.float32), (joints + offset).astype(np.float32))
        return self._rest[shape]

    def rest_batch(self, shapes: list[AnnyShape], chunk: int = 128) -> tuple[np.ndarray, np.ndarray]:
        """Rest vertices ``(S, V, 3)`` and joints ``(S, J, 3)`` (float32, loosefit's frame) of many shapes in
        batched model calls: about 1.3 ms a shape at full resolution against 30 ms one by one (the body-shape
        search of :mod:`loosefit.garment.shape_profile` looks at hundreds). Nothing is cached."""
        model = load_anny(self.rig, TOPOLOGIES[self.resolution])
        names = AnnyShape.names()
        values = np.array([[getattr(s, k) for k in names] for s in shapes], np.float64).reshape(-1, len(names))
        verts_out, joints_out = [], []
        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # half the CPU time of two threads on the 2-core machines, and no slower
        try:
            for start in range(0, len(values), chunk):
                verts, joints = self._rest_chunk(model, values[start:start + chunk], shapes[start:start + chunk])
                verts_out.append(verts)
                joints_out.append(joints)
        finally:
            torch.set_num_threads(threads)
        return np.concatenate(verts_out), np.concatenate(joints_out)

    def _rest_chunk(self, model, values: np.ndarray, shapes: list[AnnyShape]) -> tuple[np.ndarray, np.ndarray]:
        names = AnnyShape.names()
        part = torch.as_tensor(values, dtype=model.dtype)
        pose = torch.eye(4, dtype=model.dtype).expand(len(part), model.bone_count, 4, 4).clone()
        with torch.no_grad():
            out = model(pose_parameters=pose, phenotype_kwargs={k: part[:, i] for i, k in enumerate(names)})
        verts, joints = out["rest_vertices"].numpy(), out["rest_bone_heads"].numpy()
        if self.resolution == "full":  # as floor_offset, from this very mesh
            offset = np.concatenate([-joints[:, :1, :2], -verts[:, :, 2:].min(1, keepdims=True)], 2)
        else:
            offset = np.stack([floor_offset(self.rig, s) for s in shapes])[:, None]
        return (verts + offset).astype(np.float32), (joints + offset).astype(np.float32)

    def anny_offset(self, shape=None) -> np.ndarray:
        """``(3,)`` float64: loosefit frame = Anny frame + this offset."""
        return floor_offset(self.rig, self._resolve(shape))

    def collision_proxy(self) -> "AnnyBody":
        """The same body at low resolution (1,229 vertices), in the same frame, for simulation
        and collision checks (made once per body and shape: each motion's collision handling asks for it)."""
        if self.resolution == "low":
            return self
        if self._proxy is None or self._proxy.shape != self.shape:
            self._proxy = AnnyBody(self.shape, "low", self.rig)
        return self._proxy


@functools.lru_cache(maxsize=64)
def floor_offset(rig: str, shape: AnnyShape) -> np.ndarray:
    """Offset putting the full-resolution rest body's soles on ``z = 0`` and its root above the origin.

    Always measured on the full mesh so that every resolution of a body shares one frame.
    """
    verts, joints = anny_rest_pose(load_anny(rig, TOPOLOGIES["full"]), shape)
    return np.array([-joints[0, 0], -joints[0, 1], -verts[:, 2].min()])
