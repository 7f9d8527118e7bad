"""Shared helpers of the mesh-sequence format tests."""

import numpy as np

from loosefit.io.mesh_sequence import MeshSequence


def random_sequence(seed=0, frames=10, verts=50, fps=24.0, body=True) -> MeshSequence:
    """A random garment (``verts`` vertices, 80 triangles of three distinct corners) and, with ``body``,
    a body (20 vertices, 30 triangles) over ``frames`` frames."""
    rng = np.random.default_rng(seed)
    faces = np.argsort(rng.random((80, verts)), axis=1)[:, :3]
    extra = {
        "body_verts": rng.normal(size=(frames, 20, 3)).astype(np.float32),
        "body_faces": np.argsort(rng.random((30, 20)), axis=1)[:, :3],
    }
    return MeshSequence(rng.normal(size=(frames, verts, 3)), faces, fps, extra if body else {})


def blender_skinned_frames(path, names, frames, fps):
    """Blender's glTF importer on ``path``: the evaluated (skinned, animated) world vertices ``(frames, V, 3)``
    float64 of each object in ``names`` at scene frames ``0 .. frames-1`` (keyframe ``t / fps`` s at frame ``t``)."""
    import bpy
    import addon_utils  # importable once bpy is

    bpy.ops.wm.read_factory_settings(use_empty=True)
    try:
        addon_utils.enable("io_scene_gltf2")
        scene = bpy.context.scene
        scene.render.fps, scene.render.fps_base = int(round(fps)), int(round(fps)) / fps
        bpy.ops.import_scene.gltf(filepath=str(path))
        out = {name: [] for name in names}
        for frame in range(frames):
            scene.frame_set(frame)
            depsgraph = bpy.context.evaluated_depsgraph_get()
            for name in names:
                obj = bpy.data.objects[name].evaluated_get(depsgraph)
                points = np.empty(len(obj.data.vertices) * 3, np.float32)
                obj.data.vertices.foreach_get("co", points)
                world = np.array(obj.matrix_world)
                out[name].append(points.reshape(-1, 3).astype(np.float64) @ world[:3, :3].T + world[:3, 3])
        return {name: np.stack(v) for name, v in out.items()}
    finally:
        bpy.ops.wm.read_factory_settings(use_empty=True)
