"""Wavefront OBJ files: atomic writing and reading of vertices and triangles."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loosefit.errors import InputError
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
        np.savetxt(f, verts, fmt="v %.9g %.9g %.9g")
        np.savetxt(f, faces + 1, fmt="f %d %d %d")


def read_obj(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read the vertices and triangles of an OBJ file.

    Returns ``(verts (V, 3) float32, faces (F, 3) int64 0-based)``. Face entries may be ``v``,
    ``v/vt``, ``v/vt/vn`` or ``v//vn`` (only ``v`` is kept) and negative (relative) indices; other
    records (normals, texture coordinates, groups, materials) are ignored. Polygons with more than
    three corners are refused.
    """
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read OBJ file: {e}", path) from None
    coords: list[str] = []
    corners: list[str] = []
    for number, line in enumerate(lines, 1):
        if line.startswith("v "):
            xyz = line.split()[1:4]
            if len(xyz) != 3:
                raise InputError(f"line {number}: vertex with {len(xyz)} coordinates", path)
            coords.extend(xyz)
        elif line.startswith("f "):
            tokens = line.split()[1:]
            if len(tokens) != 3:
                raise InputError(f"line {number}: face with {len(tokens)} corners, only triangles are read", path)
            corners.extend(token.split("/", 1)[0] for token in tokens)
    try:
        verts = np.array(coords, dtype=np.float64).reshape(-1, 3).astype(np.float32)
        faces = np.array(corners, dtype=np.int64).reshape(-1, 3)
    except ValueError as e:
        raise InputError(f"malformed vertex or face record: {e}", path) from None
    faces = np.where(faces < 0, faces + len(verts), faces - 1)  # OBJ: 1-based, negative = from the end
    if faces.size and (faces.min() < 0 or faces.max() >= len(verts)):
        raise InputError(f"faces index vertices outside [1, {len(verts)}]", path)
    return verts, faces
