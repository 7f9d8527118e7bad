"""Mesh sequences as Alembic (``.abc``) files, written and read through Blender (``bpy``).

Writing: the garment (and the body, when the sequence has one) becomes a Blender mesh object driven
by a Mesh Cache modifier reading a temporary ``.pc2`` (frame ``t`` at scene frame ``t + 1``), and
Blender's Alembic exporter writes the evaluated mesh of every frame as objects ``garment`` / ``body``,
scene frame rate = ``fps``. Reading: Blender's Alembic importer, then the mesh evaluated at every
frame of the imported range. Blender converts Z-up to Alembic's Y-up on export and back on import,
and stores float32 positions, so the round trip is bit-exact in loosefit's frame.

Alembic files keep their frame rate in the time sampling, which Blender's importer does not expose;
the reader takes it from the ``FramesPerTimeUnit`` archive metadata Blender writes, and for files
without it samples the animation at 30 fps. Polygons are triangulated on read.

Both functions reset Blender's scene (``read_factory_settings``) before and after: whatever a caller
had built in ``bpy`` in this process is discarded. ``bpy`` is imported on first use (~1 s).
"""

from __future__ import annotations

import mmap
import re
import tempfile
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.interrupts import held_signals
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.paths import atomic_path
from loosefit.io.pc2 import write_pc2

_FPS_METADATA = re.compile(rb"FramesPerTimeUnit=([0-9]+(?:\.[0-9]*)?)")


def write_alembic(path: str | Path, seq: MeshSequence) -> None:
    """Write ``seq`` (garment, and body if ``seq.extra`` has ``body_verts``/``body_faces``) to an ``.abc`` file.

    A Ctrl-C or SIGTERM waits until the file is written (:func:`loosefit.interrupts.held_signals`: Blender's
    operators would swallow it)."""
    with held_signals():
        _write_alembic(path, seq)


def _write_alembic(path: str | Path, seq: MeshSequence) -> None:
    from loosefit.extras import require

    bpy = require("bpy", "Alembic export (through Blender)")

    meshes = [("garment", seq.verts, seq.faces)]
    if "body_verts" in seq.extra:
        meshes.append(("body", np.asarray(seq.extra["body_verts"], np.float32), seq.extra["body_faces"]))
    num_frames = len(seq.verts)
    with tempfile.TemporaryDirectory(prefix="loosefit-abc-") as workdir:
        scene = _reset_scene(bpy, seq.fps)
        scene.frame_start, scene.frame_end = 1, num_frames
        for name, verts, faces in meshes:
            obj = mesh_object(bpy, scene, name, verts[0], faces)
            cache_path = Path(workdir) / f"{name}.pc2"
            write_pc2(cache_path, verts)
            cache = obj.modifiers.new("cache", "MESH_CACHE")
            cache.cache_format = "PC2"
            cache.filepath = str(cache_path)
            cache.frame_start = 1.0
            cache.forward_axis, cache.up_axis = "POS_Y", "POS_Z"  # the cache is already in Blender's frame
        try:
            with atomic_path(path) as tmp:
                # no normals: Blender would write flat per-corner normals; readers compute smooth ones
                result = bpy.ops.wm.alembic_export(
                    filepath=str(tmp), start=1, end=num_frames, uvs=False, normals=False, as_background_job=False
                )
                if "FINISHED" not in result:
                    raise InputError("Blender's Alembic exporter failed", path)
        finally:
            bpy.ops.wm.read_factory_settings(use_empty=True)


def read_alembic(path: str | Path) -> MeshSequence:
    """Read an ``.abc`` mesh sequence: object ``garment`` (else the first mesh) and ``body`` if present.

    Returns a Z-up :class:`MeshSequence`, one frame per frame of the file's time range at its frame rate. A
    Ctrl-C or SIGTERM waits until the file is read, as in :func:`write_alembic`.
    """
    with held_signals():
        return _read_alembic(path)


def _read_alembic(path: str | Path) -> MeshSequence:
    import bpy

    path = Path(path)
    fps = _metadata_fps(path)
    scene = _reset_scene(bpy, fps)
    try:
        try:
            result = bpy.ops.wm.alembic_import(filepath=str(path), set_frame_range=True, as_background_job=False)
        except RuntimeError:  # an operator may raise its reported error instead of returning CANCELLED
            result = set()
        if "FINISHED" not in result:
            raise InputError("Blender cannot read it as an Alembic archive", path)
        meshes = {obj.name: obj for obj in bpy.data.objects if obj.type == "MESH"}
        if not meshes:
            raise InputError("no mesh in the Alembic file", path)
        garment = meshes.get("garment", meshes[sorted(meshes)[0]])
        animated = any(m.type == "MESH_SEQUENCE_CACHE" for m in garment.modifiers)
        frames = range(scene.frame_start, scene.frame_end + 1) if animated else [scene.frame_start]
        objects = [garment] + ([meshes["body"]] if "garment" in meshes and "body" in meshes else [])
        sampled = _sample(bpy, scene, objects, frames, path)
    finally:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    verts, faces = sampled[0]
    extra = {"body_verts": sampled[1][0], "body_faces": sampled[1][1]} if len(sampled) > 1 else {}
    return MeshSequence(verts, faces, fps, extra)


def _metadata_fps(path: Path) -> float:
    """The ``FramesPerTimeUnit`` archive metadata of an Alembic file written by Blender (30 when absent)."""
    try:
        with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as raw:
            match = _FPS_METADATA.search(raw)
            value = bytes(match.group(1)) if match else None
    except (OSError, ValueError) as e:  # ValueError: an empty file cannot be mapped
        raise InputError(f"cannot read Alembic file: {e}", path) from None
    return float(value) if value else 30.0


def _reset_scene(bpy, fps: float):
    """An empty Blender scene running at ``fps`` (integer ``render.fps`` scaled by ``fps_base``)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = max(1, int(round(fps)))
    scene.render.fps_base = scene.render.fps / fps
    return scene


def mesh_object(bpy, scene, name: str, verts: np.ndarray, faces: np.ndarray):
    """A mesh object ``name`` with ``verts (V, 3)`` and triangles ``faces (F, 3)``, linked to ``scene``."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.asarray(verts, np.float64).tolist(), [], np.asarray(faces).tolist())
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def _sample(bpy, scene, objects: list, frames, path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Evaluate ``objects`` at scene ``frames``: per object ``(verts (T, V, 3) float32 world, faces (F, 3) int64)``."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    verts = [[] for _ in objects]
    faces = []
    for frame in frames:
        scene.frame_set(frame)
        for i, obj in enumerate(objects):
            evaluated = obj.evaluated_get(depsgraph)
            mesh = evaluated.data
            points = np.empty(len(mesh.vertices) * 3, np.float32)
            mesh.vertices.foreach_get("co", points)
            points = points.reshape(-1, 3).astype(np.float64)
            world = np.array(evaluated.matrix_world)
            if verts[i] and len(points) != len(verts[i][0]):
                raise InputError(f"object {obj.name!r} changes vertex count at frame {frame}", path)
            verts[i].append(points @ world[:3, :3].T + world[:3, 3])  # column-vector matrix
            if len(faces) == i:
                mesh.calc_loop_triangles()
                triangles = np.empty(len(mesh.loop_triangles) * 3, np.int32)  # Blender's int width: a direct copy
                mesh.loop_triangles.foreach_get("vertices", triangles)
                faces.append(triangles.reshape(-1, 3).astype(np.int64))
    return [(np.asarray(v, np.float32), f) for v, f in zip(verts, faces)]
