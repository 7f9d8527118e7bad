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
