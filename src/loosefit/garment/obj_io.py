"""Reading Wavefront OBJ meshes (vertices and polygon faces), reporting malformed lines."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loosefit.errors import InputError

IGNORED = {"vt", "vn", "vp", "o", "g", "s", "usemtl", "mtllib", "l", "p", "cstype", "deg", "curv", "parm", "end"}


def read_obj(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Parse an OBJ: ``v`` lines and polygon ``f`` lines (fan-triangulated, 1-based or negative
    relative indices, ``i/t/n`` forms). Returns ``verts (V, 3)`` float64 and ``faces (F, 3)`` int64."""
    verts, faces, _, _ = read_obj_numbered(path)
    return verts, faces


def read_obj_numbered(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`read_obj` with where each triangle comes from in the file: returns ``verts (V, 3)``, ``faces (F, 3)``
    (vertex ``i`` is the file's ``v`` line number ``i + 1`` in OBJ's counting), ``polygon (F,)`` int64 the 0-based
    index of the ``f`` statement each triangle was cut from (a quad gives two triangles of one polygon) and
    ``line (F,)`` int64 that statement's line number (from 1)."""
    verts, faces = [], []
    with open(path, encoding="utf-8", errors="replace") as fh:
        polygons = 0
        for lineno, raw in enumerate(fh, 1):
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            key, *rest = line.split()
            if key == "v":
                if len(rest) < 3:
                    raise InputError(f"line {lineno}: a vertex needs 3 coordinates: {raw.strip()!r}", path)
                try:
                    verts.append([float(x) for x in rest[:3]])
                except ValueError:
                    raise InputError(f"line {lineno}: vertex coordinates are not numbers: {raw.strip()!r}", path) from None
            elif key == "f":
                if len(rest) < 3:
                    raise InputError(f"line {lineno}: a face needs at least 3 vertices: {raw.strip()!r}", path)
                try:
                    ids = [int(x.split("/")[0]) for x in rest]
                except ValueError:
                    raise InputError(f"line {lineno}: face indices are not integers: {raw.strip()!r}", path) from None
                # 1-based, or relative to the vertices read so far when negative.
                ids = [i - 1 if i > 0 else len(verts) + i if i < 0 else -1 for i in ids]
                faces += [(lineno, raw.strip(), polygons, [ids[0], ids[k], ids[k + 1]]) for k in range(1, len(ids) - 1)]
                polygons += 1
            elif key not in IGNORED:
                raise InputError(f"line {lineno}: not an OBJ statement: {raw.strip()[:60]!r}", path)
    for lineno, text, _, ids in faces:
        if not all(0 <= i < len(verts) for i in ids):
            raise InputError(f"line {lineno}: face index out of range 1..{len(verts)}: {text!r}", path)
    tris = np.asarray([ids for *_, ids in faces], dtype=np.int64).reshape(-1, 3)
    polygon = np.asarray([k for _, _, k, _ in faces], dtype=np.int64)
    lines = np.asarray([n for n, *_ in faces], dtype=np.int64)
    return np.asarray(verts, dtype=np.float64).reshape(-1, 3), tris, polygon, lines
