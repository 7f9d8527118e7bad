"""A garment mesh file (OBJ or PLY) read with its own numbering, so that what is wrong with it can be
named as the file numbers it.

The importer renumbers what it reads: coincident vertices are welded into the first of them, split
vertices get appended copies, unused ones are dropped, degenerate and duplicate faces go, polygons
become triangles. :class:`FileNumbers` follows every vertex and triangle through these steps back to
the file: OBJ counts vertices and faces from 1 (and a face is also named by its line), PLY from 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.garment.obj_io import read_obj_numbered

#: How many offending vertices or faces a message names (then "..." and the count).
SHOWN = 5


@dataclass
class FileNumbers:
    """Where each vertex and triangle of a mesh comes from in its file.

    Attributes:
        vertex: ``(V,)`` int64, each vertex's 0-based position among the file's vertices (a welded vertex:
            the first of the file's vertices merged into it; a split copy: the vertex it copies).
        face: ``(F,)`` int64, each triangle's 0-based position among the file's faces (polygons: a quad's
            two triangles share one).
        line: ``(F,)`` int64 line number of each triangle's face statement (OBJ), or ``None`` (PLY).
        base: the file format's first number: 1 for OBJ, 0 for PLY.
        unit: what :attr:`face` counts: ``"face"``, or ``"triangle"`` when the file's polygons could not be
            followed (a PLY of mixed polygons in a layout not understood).
    """

    vertex: np.ndarray
    face: np.ndarray
    line: np.ndarray | None = None
    base: int = 0
    unit: str = "face"

    @classmethod
    def identity(cls, num_verts: int, num_faces: int, base: int = 0) -> "FileNumbers":
        """The numbering of a mesh read as is (vertex ``i`` is the file's ``i``)."""
        return cls(np.arange(num_verts, dtype=np.int64), np.arange(num_faces, dtype=np.int64), None, base)

    def select(self, vertex: np.ndarray | None = None, face: np.ndarray | None = None) -> "FileNumbers":
        """The numbering after a step that made vertex ``j`` from old vertex ``vertex[j]`` and triangle ``k``
        from old triangle ``face[k]`` (``None``: unchanged)."""
        v = self.vertex if vertex is None else self.vertex[np.asarray(vertex, np.int64)]
        if face is None:
            return FileNumbers(v, self.face, self.line, self.base, self.unit)
        face = np.asarray(face, np.int64)
        return FileNumbers(v, self.face[face], None if self.line is None else self.line[face], self.base, self.unit)

    def after_faces(self, num_verts: int, old_faces: np.ndarray, new_faces: np.ndarray) -> "FileNumbers":
        """The numbering after a step that kept the triangles in order but renumbered their corners
        (``new_faces[k, c]`` is a copy of ``old_faces[k, c]``, ``num_verts`` vertices now)."""
        vertex = np.zeros(num_verts, np.int64)
        known = min(num_verts, len(self.vertex))
        vertex[:known] = self.vertex[:known]
        vertex[np.asarray(new_faces).reshape(-1)] = self.vertex[np.asarray(old_faces).reshape(-1)]
        return FileNumbers(vertex, self.face, self.line, self.base, self.unit)

    def vertices(self, ids, limit: int = SHOWN) -> str:
        """The file's numbers of vertices ``ids`` (the first ``limit``): ``"5, 9, 12"``."""
        numbers = list(dict.fromkeys(int(self.vertex[i]) + self.base for i in np.asarray(ids, np.int64).ravel()))
        return _listing(numbers, limit)

    def edges(self, pairs, limit: int = SHOWN) -> str:
        """Edges ``pairs (E, 2)`` by their ends' file numbers: ``"5-9, 12-40"``."""
        pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
        return _listing([f"{self.vertex[a] + self.base}-{self.vertex[b] + self.base}" for a, b in pairs[:limit]],
                        limit, len(pairs))

    def faces(self, ids, limit: int = SHOWN) -> str:
        """The file's numbers of triangles ``ids`` (their polygons, once each), with their lines (OBJ):
        ``"12 (line 40), 13 (line 41)"``."""
        seen: dict[int, str] = {}
        for k in np.asarray(ids, np.int64).ravel():
            number = int(self.face[k]) + self.base
            if number not in seen:
                seen[number] = str(number) if self.line is None else f"{number} (line {int(self.line[k])})"
        return _listing(list(seen.values()), limit)


def _listing(items: list, limit: int, total: int | None = None) -> str:
    total = len(items) if total is None else total
    text = ", ".join(str(x) for x in items[:limit])
    return text + (f", ... ({total} in all)" if total > limit else "")


def read_mesh_file(path: str | Path) -> tuple[np.ndarray, np.ndarray, FileNumbers]:
    """Read a garment mesh: ``verts (V, 3)`` float64 as in the file, ``faces (F, 3)`` int64 triangles (polygons
    fan-triangulated) and their :class:`FileNumbers`.

    Raises:
        InputError: no such file, a format other than .obj / .ply, an unreadable file (naming the line for OBJ).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", path)
    suffix = path.suffix.lower()
    if suffix == ".obj":
        verts, faces, polygon, line = read_obj_numbered(path)
        return verts, faces, FileNumbers(np.arange(len(verts), dtype=np.int64), polygon, line, base=1)
    if suffix == ".ply":
        verts, faces, polygon = _read_ply_numbered(path)
        numbers = FileNumbers(np.arange(len(verts), dtype=np.int64), np.arange(len(faces), dtype=np.int64), None, 0)
        if polygon is None:
            numbers.unit = "triangle"
        else:
            numbers.face = polygon
        return verts, faces, numbers
    raise InputError(f"unsupported garment format {suffix!r}; use .obj or .ply", path)


def read_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a PLY mesh through trimesh (no processing). Returns ``(verts, faces)``."""
    verts, faces, _ = _read_ply_numbered(path)
    return verts, faces


def _read_ply_numbered(path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(verts, faces, polygon)``: ``polygon (F,)`` the 0-based file face of each triangle, ``None`` when the
    file's polygons could not be followed (then the triangles are trimesh's)."""
    import trimesh

    try:
        mesh = trimesh.load(str(path), file_type="ply", process=False, force="mesh")
    except Exception as err:  # trimesh raises many types on malformed files
        raise InputError(f"unreadable PLY: {err}", path) from None
    verts = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    polygons = _ply_polygons(getattr(mesh, "metadata", {}))
    if polygons is None:
        return verts, faces, None
    if all(len(p) == 3 for p in polygons) and len(polygons) == len(faces):
        return verts, faces, np.arange(len(faces), dtype=np.int64)  # trimesh keeps a file of triangles in order
    # Mixed polygons: trimesh groups them by size, so fan them here in the file's order.
    tris = [(k, [p[0], p[i], p[i + 1]]) for k, p in enumerate(polygons) for i in range(1, len(p) - 1)]
    faces = np.asarray([t for _, t in tris], dtype=np.int64).reshape(-1, 3)
    if len(faces) and (faces.min() < 0 or faces.max() >= len(verts)):
        raise InputError(f"a face index is out of range 0..{len(verts) - 1}", path)
    return verts, faces, np.asarray([k for k, _ in tris], dtype=np.int64)


def _ply_polygons(metadata: dict) -> list[list[int]] | None:
    """The vertex lists of a PLY's faces in file order, from trimesh's raw PLY elements; ``None`` when their
    layout is not one of those known (trimesh 4-5: a dict of arrays for ASCII, a structured array for binary)."""
    try:
        data = metadata["_ply_raw"]["face"]["data"]
        if isinstance(data, dict):
            name = next(k for k in data if k.startswith("vertex_ind"))
            lists = data[name]
        else:
            name = next(k for k in data.dtype.names if k.startswith("vertex_ind"))
            lists = data[name]
            if lists.dtype.names:  # (count, indices) records
                lists = lists[lists.dtype.names[-1]]
        return [[int(i) for i in np.asarray(p).ravel()] for p in lists]
    except (KeyError, TypeError, StopIteration, AttributeError, ValueError):
        return None
