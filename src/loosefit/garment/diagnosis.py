"""What is wrong with a garment mesh, counted and named in its file's own numbers.

:func:`diagnose` counts, on the triangles as read (after coincident vertices are welded, as the importer
does, so that panels written with their own seam vertices count as joined):

- pieces: connected components (faces joined through shared vertices);
- degenerate faces: a vertex repeated, or no area;
- duplicate faces: the same three vertices as an earlier face, in any order;
- non-manifold edges: edges of more than two faces (duplicates and degenerate faces not counted);
- pinched vertices: vertices whose faces form more than one fan (two sheets touching at a point);
- open boundary loops: loops of edges with one face, and the boundary vertices where a loop is not
  simple (more than two boundary edges meet);
- non-orientable pieces: sheets (faces glued along two-face edges) whose faces cannot all be wound the
  same way, and the faces wound against most of their sheet (which re-orienting fixes).

Each count comes with the first few offending vertices or faces as the file numbers them
(:class:`~loosefit.garment.mesh_file.FileNumbers`: from 1 in OBJ, with the face's line; from 0 in PLY).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from loosefit.garment.mesh_checks import face_areas, face_components, nonmanifold_vertices, orientation, unique_edges
from loosefit.garment.mesh_file import FileNumbers

#: Faces with less area than this fraction of the bounding-box diagonal, squared, are degenerate (as the importer).
DEGENERATE_AREA = 1e-14


_SINGULAR = {"edges": "edge", "faces": "face", "loops": "loop", "pieces": "piece", "vertices": "vertex"}


def counted(n: int, phrase: str) -> str:
    """``"3 duplicate faces"``, ``"1 duplicate face"``: ``phrase`` in the plural, its first noun made singular
    for one."""
    if n == 1:
        words = phrase.split(" ")
        i = next((k for k, w in enumerate(words) if w in _SINGULAR), None)
        if i is not None:
            words[i] = _SINGULAR[words[i]]
        phrase = " ".join(words)
    return f"{n} {phrase}"


@dataclass
class Diagnosis:
    """Counts of what is wrong with a mesh, each with the file's numbers of its first offenders (text)."""

    num_verts: int
    num_faces: int
    pieces: int
    degenerate_faces: int = 0
    duplicate_faces: int = 0
    nonmanifold_edges: int = 0
    pinched_vertices: int = 0
    boundary_loops: int = 0
    open_boundary_vertices: int = 0
    nonorientable_pieces: int = 0
    misoriented_faces: int = 0
    examples: dict | None = None

    @property
    def clean(self) -> bool:
        """A manifold surface, wound consistently, without degenerate or duplicate faces (pieces and boundary
        loops may be any number: whether that is a garment is for :func:`~loosefit.garment.importer.check_wearable`)."""
        return not (self.degenerate_faces or self.duplicate_faces or self.nonmanifold_edges or self.pinched_vertices
                    or self.open_boundary_vertices or self.nonorientable_pieces or self.misoriented_faces)

    def counts(self) -> dict[str, int]:
        """The counts by name (JSON-able)."""
        names = ("pieces", "degenerate_faces", "duplicate_faces", "nonmanifold_edges", "pinched_vertices",
                 "boundary_loops", "open_boundary_vertices", "nonorientable_pieces", "misoriented_faces")
        return {k: int(getattr(self, k)) for k in names}

    def text(self) -> str:
        """One line for people: every count, with the first offenders of those that are not zero."""
        ex = self.examples or {}

        def item(count: int, what: str, key: str | None = None) -> str:
            return counted(count, what) + (f" ({ex[key]})" if count and key in ex else "")

        parts = [
            item(self.pieces, "pieces"),
            item(self.nonmanifold_edges, "non-manifold edges (more than 2 faces)", "nonmanifold_edges"),
            item(self.duplicate_faces, "duplicate faces", "duplicate_faces"),
            item(self.degenerate_faces, "degenerate faces", "degenerate_faces"),
            item(self.boundary_loops, "open boundary loops")
            + (f", {item(self.open_boundary_vertices, 'vertices where a boundary is not a simple loop', 'open_boundary_vertices')}"
               if self.open_boundary_vertices else ""),
            item(self.nonorientable_pieces, "non-orientable pieces", "nonorientable_pieces"),
        ]
        if self.pinched_vertices:
            parts.append(item(self.pinched_vertices, "pinched vertices (two sheets touching at a point)",
                              "pinched_vertices"))
        if self.misoriented_faces:
            parts.append(item(self.misoriented_faces, "faces wound against their neighbours", "misoriented_faces"))
        return "; ".join(parts)


def diagnose(verts: np.ndarray, faces: np.ndarray, numbers: FileNumbers | None = None) -> Diagnosis:
    """Count what is wrong with a triangle mesh (module docstring).

    Args:
        verts: ``(V, 3)`` positions (any unit).
        faces: ``(F, 3)`` int triangles.
        numbers: where vertices and faces are in the file (default: as given, from 0).

    Returns:
        A :class:`Diagnosis`; its ``examples`` name the first offenders in the file's numbers.
    """
    verts = np.asarray(verts, np.float64)
    faces = np.asarray(faces, np.int64)
    numbers = numbers or FileNumbers.identity(len(verts), len(faces))
    nv, nf = len(verts), len(faces)
    if nf == 0:
        return Diagnosis(nv, 0, 0, examples={})
    word = numbers.unit + "s"
    ex: dict[str, str] = {}
    diag = float(np.linalg.norm(verts.max(0) - verts.min(0))) if nv else 0.0
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    degenerate = repeated | (face_areas(verts, faces) <= DEGENERATE_AREA * diag ** 2)
    if degenerate.any():
        ex["degenerate_faces"] = f"{word} " + numbers.faces(np.nonzero(degenerate)[0])
    key = np.sort(faces, 1)
    key = (key[:, 0] * nv + key[:, 1]) * nv + key[:, 2]
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    duplicate = np.ones(nf, bool)
    duplicate[first] = False
    duplicate &= ~degenerate
    if duplicate.any():
        dup = np.nonzero(duplicate)[0]
        shown = [f"{numbers.faces([k])} repeats {numbers.faces([first[inverse[k]]])}" for k in dup[:3]]
        ex["duplicate_faces"] = f"{numbers.unit} " + "; ".join(shown) + (f"; ... ({len(dup)} in all)" if len(dup) > 3 else "")
    keep = np.nonzero(~degenerate & ~duplicate)[0]
    clean = faces[keep]
    out = Diagnosis(nv, nf, 0, int(degenerate.sum()), int(duplicate.sum()), examples=ex)
    if len(clean) == 0:
        return out
    out.pieces = int(face_components(clean).max() + 1)
    edges, _, count = unique_edges(clean)
    over = count > 2
    out.nonmanifold_edges = int(over.sum())
    if over.any():
        worst = np.argsort(-count, kind="stable")[: int(over.sum())]
        worst = np.sort(worst)  # file order, as the user will look them up
        ex["nonmanifold_edges"] = "vertices " + ", ".join(
            f"{numbers.edges(edges[[e]])} with {count[e]} faces" for e in worst[:3]) + (
            f", ... ({len(worst)} in all)" if len(worst) > 3 else "")
    pinched = nonmanifold_vertices(nv, clean)
    # A vertex on a non-manifold edge is reported with the edge, not again as pinched.
    pinched = np.setdiff1d(pinched, edges[over].ravel())
    out.pinched_vertices = len(pinched)
    if len(pinched):
        ex["pinched_vertices"] = "vertices " + numbers.vertices(pinched)
    border = edges[count == 1]
    if len(border):
        degree = np.bincount(border.ravel(), minlength=nv)
        graph = sp.coo_matrix((np.ones(len(border)), (border[:, 0], border[:, 1])), shape=(nv, nv))
        _, label = connected_components(graph, directed=False)
        out.boundary_loops = len(np.unique(label[border[:, 0]]))
        odd = np.nonzero(degree > 2)[0]
        out.open_boundary_vertices = len(odd)
        if len(odd):
            ex["open_boundary_vertices"] = "vertices " + numbers.vertices(odd)
    flip, conflicts, sheet = orientation(clean)
    if len(conflicts):
        bad = np.unique(sheet[conflicts[:, 0]])
        out.nonorientable_pieces = len(bad)
        ex["nonorientable_pieces"] = f"where {word} " + numbers.faces(keep[conflicts[:, 0]]) + " meet their neighbours"
    good = ~np.isin(sheet, np.unique(sheet[conflicts[:, 0]]))  # a non-orientable sheet has no right side
    out.misoriented_faces = int((flip & good).sum())
    if out.misoriented_faces:
        ex["misoriented_faces"] = f"{word} " + numbers.faces(keep[flip & good])
    return out
