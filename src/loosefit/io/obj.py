"""Wavefront OBJ writing (vertices and triangles), atomic."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loosefit.paths import atomic_path


def write_obj(path: str | Path, verts: np.ndarray, faces: np.ndarray, header: str = "") -> None:
    """Write ``verts (V, 3)`` metres and ``faces (F, 3)`` 0-based indices to an OBJ file (1-based inside).

    ``header`` lines are written as ``#`` comments. The file appears only once complete.
    """
    verts = np.asarray(verts, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    with atomic_path(path) as tmp, open(tmp, "w") as f:
        for line in header.splitlines():
            f.write(f"# {line}\n")
        np.savetxt(f, verts, fmt="v %.7g %.7g %.7g")
        np.savetxt(f, faces + 1, fmt="f %d %d %d")
