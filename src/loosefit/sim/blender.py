"""Blender cloth (``bpy``) as the simulation backend. ``bpy`` is imported inside :func:`run_cloth` only.

Scene per run (reset to factory settings first): the body collider driven per frame by a Mesh
Cache modifier reading a ``.pc2`` file, with a Collision modifier; a static floor plane at the
height of the soles on the ground (:func:`_floor`); the garment with a Mesh Cache
modifier (the garment skinned to the body) under a Cloth modifier whose pin group holds the
pinned vertices, so that they follow the body exactly. Frames are stepped in order and the cloth
positions read back after each.

Unit mapping (:func:`cloth_settings`). Blender's cloth solver counts time in frames, takes vertex
masses in kg and forces in kg*m/frame^2, and scales spring stiffness by the mean edge length
``L``. With ``f`` the frame rate, ``A`` the garment area and ``V`` its vertex count:

- vertex mass = ``density * A / V`` (kg);
- tension / compression / shear stiffness = ``k * L / f^2`` for ``k`` in N/m (a spring carries
  the force across a strip about ``L`` wide);
- angular bending stiffness = ``10 * B / (L^2 f^2)`` for rigidity ``B`` in N*m (Blender's hinge
  force is ``0.1 * stiffness * L * angle``; a hinge of width ``L`` and lever ``L`` needs ``B * angle / L``);
- spring damping = ``rate * m / f`` so that relative velocities decay at ``rate`` per second;
- air viscosity = ``100 * drag * (A / V) / f`` (Blender's drag is ``0.01 * viscosity`` per vertex);
- gravity: Blender scales the scene gravity by 0.001 per frame^2, so the scene gets ``1000 * g / f^2``.

The constant in the bending mapping is a convention; the physical defaults of
:class:`~loosefit.sim.params.SimParams` were tuned by eye with it.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from loosefit.extras import require
from loosefit.interrupts import held_signals
from loosefit.geometry.laplacian import edges
from loosefit.geometry.normals import face_areas
from loosefit.io.alembic import mesh_object
from loosefit.io.pc2 import write_pc2
from loosefit.sim.params import SimParams

#: Smallest collision thickness Blender accepts on a collider, m; the rest of the distance is the cloth's.
_BODY_THICKNESS = 0.001


def cloth_settings(params: SimParams, verts: np.ndarray, faces: np.ndarray, fps: float) -> dict[str, float]:
    """Blender ``ClothSettings`` values for ``params`` on the mesh ``verts (V, 3)``, ``faces (F, 3)`` at ``fps``."""
    area = float(face_areas(verts, faces).sum())
    e = edges(faces)
    mean_edge = float(np.linalg.norm(verts[e[:, 0]] - verts[e[:, 1]], axis=1).mean())
    mass = params.density * area / len(verts)
    per_frame2 = 1.0 / fps**2
    per_rate = mass / fps  # damping coefficient (kg per frame) of a decay rate of 1/s
    return {
        "mass": mass,
        "tension_stiffness": params.tension * mean_edge * per_frame2,
        "compression_stiffness": params.compression * mean_edge * per_frame2,
        "shear_stiffness": params.shear * mean_edge * per_frame2,
        "bending_stiffness": 10.0 * params.bending / mean_edge**2 * per_frame2,
        "tension_damping": params.stretch_damping * per_rate,
        "compression_damping": params.stretch_damping * per_rate,
        "shear_damping": params.stretch_damping * per_rate,
        "bending_damping": params.bending_damping * per_rate,
        "air_damping": 100.0 * params.air_drag * area / len(verts) / fps,
        "quality": params.quality,
        "time_scale": params.time_scale,
    }


def scene_gravity(params: SimParams, fps: float) -> float:
    """Scene gravity (along -Z) that makes Blender's cloth fall at ``params.gravity`` m/s^2."""
    return 1000.0 * params.gravity / fps**2


def run_cloth(
    faces: np.ndarray,
    pinned: np.ndarray,
    garment_frames: np.ndarray,
    collider_frames: np.ndarray,
    collider_faces: np.ndarray,
    params: SimParams,
    fps: float,
    workdir: str | Path | None = None,
    floor: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate a garment on a moving collider with Blender cloth.

    Args:
        faces: ``(F, 3)`` garment triangles.
        pinned: ``(V,)`` bool, vertices that follow ``garment_frames`` exactly.
        garment_frames: ``(N, V, 3)`` garment skinned to the body; frame 0 is the start state and
            rest shape of the cloth, later frames are targets for the pinned vertices only.
        collider_frames: ``(N, Vc, 3)`` body collider vertices per frame.
        collider_faces: ``(Fc, 3)`` collider triangles.
        params: simulation parameters.
        fps: frames per second of the animation.
        workdir: folder for the ``.pc2`` caches (a temporary one when ``None``).
        floor: height of the ground, m (a collision plane there); ``None``: no ground.

    Returns:
        ``(verts (N, V, 3) float32 cloth positions per frame, seconds (N,) wall time per frame)``.
    """
    if workdir is None:
        with tempfile.TemporaryDirectory(prefix="loosefit-sim-") as tmp:
            return run_cloth(faces, pinned, garment_frames, collider_frames, collider_faces, params, fps, tmp, floor)
    bpy = require("bpy", "Blender cloth simulation")

    workdir = Path(workdir)
    num_frames, num_verts = garment_frames.shape[:2]
    write_pc2(workdir / "body.pc2", collider_frames)
    write_pc2(workdir / "garment.pc2", garment_frames)

    with held_signals():  # Blender runs its add-ons' scripts here and would swallow a Ctrl-C
        bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = int(round(fps))
    scene.render.fps_base = scene.render.fps / fps
    scene.frame_start, scene.frame_end = 1, num_frames
    scene.gravity = (0.0, 0.0, -scene_gravity(params, fps))

    body = mesh_object(bpy, scene, "body", collider_frames[0], collider_faces)
    _mesh_cache(body, workdir / "body.pc2")
    body.modifiers.new("collision", "COLLISION")
    body.collision.thickness_outer = _BODY_THICKNESS
    body.collision.thickness_inner = 0.02
    body.collision.cloth_friction = params.friction
    body.collision.damping = 0.0
    if floor is not None:
        _floor(bpy, scene, floor, np.concatenate([collider_frames, garment_frames], axis=1), params.friction)

    garment = mesh_object(bpy, scene, "garment", garment_frames[0], faces)
    group = garment.vertex_groups.new(name="pin")
    group.add(np.flatnonzero(pinned).tolist(), 1.0, "REPLACE")
    _mesh_cache(garment, workdir / "garment.pc2")
    cloth = garment.modifiers.new("cloth", "CLOTH")
    settings = cloth.settings
    for name, value in cloth_settings(params, garment_frames[0], faces, fps).items():
        setattr(settings, name, value)
    settings.vertex_group_mass = "pin"
    settings.pin_stiffness = 1.0
    collision = cloth.collision_settings
    collision.use_collision = True
    collision.distance_min = max(params.collision_distance - _BODY_THICKNESS, 0.001)
    collision.collision_quality = params.collision_quality
    collision.friction = params.friction
    collision.use_self_collision = params.self_collision
    collision.self_distance_min = max(params.self_collision_distance, 0.001)
    cloth.point_cache.frame_start, cloth.point_cache.frame_end = 1, num_frames

    out = np.empty((num_frames, num_verts, 3), np.float32)
    seconds = np.empty(num_frames)
    buf = np.empty(num_verts * 3, np.float32)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for frame in range(num_frames):
        start = time.perf_counter()
        with held_signals():  # a Ctrl-C stops the run between two frames
            scene.frame_set(frame + 1)
        garment.evaluated_get(depsgraph).data.vertices.foreach_get("co", buf)
        seconds[frame] = time.perf_counter() - start
        out[frame] = buf.reshape(num_verts, 3)
    with held_signals():
        bpy.ops.wm.read_factory_settings(use_empty=True)  # free the point cache before returning
    return out, seconds


def _floor(bpy, scene, z: float, points: np.ndarray, friction: float) -> None:
    """A static collision plane at height ``z`` under the footprint of ``points (N, P, 3)`` (body and
    garment in every frame), 2 m to spare.

    Without it a long hem sinks through the ground in a squat, a bow or a jump's landing (15 cm on
    the bench dress).
    """
    (x0, y0), (x1, y1) = points[..., :2].min((0, 1)) - 2.0, points[..., :2].max((0, 1)) + 2.0
    corners = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]])
    floor = mesh_object(bpy, scene, "floor", corners, np.array([[0, 1, 2], [0, 2, 3]]))
    floor.modifiers.new("collision", "COLLISION")
    floor.collision.thickness_outer = _BODY_THICKNESS
    floor.collision.cloth_friction = friction


def _mesh_cache(obj, path: Path) -> None:
    """Drive ``obj``'s vertices from a ``.pc2`` file: cache sample ``k`` at scene frame ``k + 1``."""
    cache = obj.modifiers.new("cache", "MESH_CACHE")
    cache.cache_format = "PC2"
    cache.filepath = str(path)
    cache.frame_start = 1.0
    cache.forward_axis, cache.up_axis = "POS_Y", "POS_Z"
