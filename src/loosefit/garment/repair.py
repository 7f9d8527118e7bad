"""``loosefit garment import --repair``: make a manifold, consistently wound garment of a messy mesh by
dropping what breaks it, and say what changed.

The import itself repairs what keeps the cloth (welds seams, drops degenerate and duplicate faces, glues
the faces of a non-manifold seam in pairs, re-orients faces; :mod:`loosefit.garment.importer`) and refuses
what it cannot, with :mod:`loosefit.garment.diagnosis`'s counts. Files exported from other tools (several
panels sewn on one edge, fins, doubled faces, loose flaps) can still be refused there: gluing the faces of
a seam of four panels in pairs can make a Moebius-like strip. :func:`repair_mesh` removes cloth instead,
least first:

1. welds coincident vertices (as the importer does);
2. drops degenerate faces (a repeated vertex, no area) and slivers (height under 1e-3 of the longest edge);
3. merges duplicate faces (the same three vertices) into the first of them;
4. on edges of more than two faces drops the faces of the smallest sheets (faces glued along two-face
   edges, by area) there, smallest first, until two faces are left, and of two faces of different sheets
   folded flat onto each other the smaller sheet's: a fin, a pocket, a doubled panel or the second
   triangulation of a quad goes, the garment's own surface stays;
5. splits pinched vertices (sheets touching at a point) into one copy per fan;
6. re-winds every orientable sheet as most of its faces are wound;
7. keeps one piece: the largest that is wearable (:func:`~loosefit.garment.importer.check_wearable`) and
   orientable, or the one ``piece`` names (1 the largest of those over 2 % of the area), and drops the rest.

Each step that changes something is one line of :meth:`RepairReport.lines` with its count and the first
faces or vertices concerned, in the file's numbers. What cannot be repaired so (no wearable orientable
piece left) is refused with the counts of what remains.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from loosefit.errors import InputError
from loosefit.garment.diagnosis import DEGENERATE_AREA, Diagnosis, counted, diagnose
from loosefit.garment.mesh_checks import face_areas, orientation, unique_edges, vertex_components
from loosefit.garment.mesh_file import FileNumbers
from loosefit.garment.seam_repair import slivers, split_nonmanifold, weld

#: Two faces on an edge that open by less than this (degrees) are folded flat onto each other: two layers
#: written over each other (two triangulations of a quad), which --repair does not glue.
FOLDED = 10.0


@dataclass
class RepairReport:
    """What :func:`repair_mesh` changed: ``changes`` maps each kind of change to ``(count, description)``
    (only kinds that changed something, in the order done); ``before`` and ``after`` diagnose the mesh
    read and the mesh returned; ``numbers`` follows the returned mesh back to the file."""

    changes: dict[str, tuple[int, str]] = field(default_factory=dict)
    before: Diagnosis | None = None
    after: Diagnosis | None = None
    numbers: FileNumbers | None = None

    def lines(self) -> list[str]:
        """One line per kind of change, for people."""
        return [text for _, text in self.changes.values()]

    def counts(self) -> dict[str, int]:
        return {k: int(n) for k, (n, _) in self.changes.items()}


def repair_mesh(verts: np.ndarray, faces: np.ndarray, numbers: FileNumbers | None = None,
                piece: str | int | None = None, path: str | Path | None = None,
                weld_fraction: float | None = None) -> tuple[np.ndarray, np.ndarray, RepairReport]:
    """Repair a messy triangle mesh into one manifold, consistently wound, wearable piece (module docstring).

    Args:
        verts: ``(V, 3)`` positions as in the file (any unit).
        faces: ``(F, 3)`` int64 triangles.
        numbers: the file's numbering of ``verts`` / ``faces`` (default: as given, from 0).
        piece: ``"largest"`` or ``N``: keep that piece (numbered from the largest, 1, among the pieces of at
            least 2 % of the area) whatever it is; ``None``: the largest wearable, orientable one.
        path: the file, named in errors.
        weld_fraction: weld distance as a fraction of the bounding-box diagonal (default: the importer's).

    Returns:
        ``(verts (V', 3), faces (F', 3), report)``: the piece kept, unused vertices removed.

    Raises:
        InputError: an empty mesh, non-finite coordinates, or no wearable, orientable piece left (the
            message counts what remains, :class:`~loosefit.garment.diagnosis.Diagnosis`, and what was changed).
    """
    from loosefit.garment.importer import PIECE_SHARE, WELD, check_wearable

    verts = np.asarray(verts, np.float64)
    faces = np.asarray(faces, np.int64)
    numbers = numbers or FileNumbers.identity(len(verts), len(faces))
    if len(verts) == 0 or len(faces) == 0:
        raise InputError("the mesh has no vertices or no faces", path)
    if not np.isfinite(verts).all():
        raise InputError("vertices have NaN or infinite coordinates", path)
    report = RepairReport()
    changes = report.changes
    word = numbers.unit + "s"

    diag = float(np.linalg.norm(verts.max(0) - verts.min(0)))
    verts, faces, merged, kept = weld(verts, faces, (WELD if weld_fraction is None else weld_fraction) * diag,
                                      return_kept=True)
    numbers = numbers.select(vertex=kept)
    report.before = diagnose(verts, faces, numbers)
    if merged:
        changes["merged_vertices"] = (merged, f"merged {counted(merged, 'coincident vertices')} (panels written with their own "
                                              "seam vertices)")

    # 2-3: faces without area, then faces written twice.
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    bad = repeated | (face_areas(verts, faces) <= DEGENERATE_AREA * diag ** 2)
    if bad.any():
        changes["degenerate_faces"] = (int(bad.sum()), f"dropped {counted(int(bad.sum()), 'degenerate faces')} (a repeated vertex "
                                       f"or no area: {word} {numbers.faces(np.nonzero(bad)[0])})")
    thin = ~bad & slivers(verts, faces)
    if thin.any():
        changes["sliver_faces"] = (int(thin.sum()), f"dropped {counted(int(thin.sum()), 'sliver faces')} (height under 1e-3 of "
                                   f"the longest edge: {word} {numbers.faces(np.nonzero(thin)[0])})")
    faces, numbers = _keep_faces(faces, numbers, ~(bad | thin))
    if len(faces) == 0:
        raise InputError("every face is degenerate", path)
    key = np.sort(faces, 1)
    _, first = np.unique((key[:, 0] * len(verts) + key[:, 1]) * len(verts) + key[:, 2], return_index=True)
    unique = np.zeros(len(faces), bool)
    unique[first] = True
    if not unique.all():
        n = int((~unique).sum())
        changes["duplicate_faces"] = (n, f"merged {counted(n, 'duplicate faces')} into the first of each ({word} "
                                      f"{numbers.faces(np.nonzero(~unique)[0])})")
    faces, numbers = _keep_faces(faces, numbers, unique)

    # 4: non-manifold edges keep the faces of their two largest sheets.
    gone, edges_fixed, folds = [], 0, 0  # the file's numbers of the faces dropped, over the rounds
    while True:
        drop, over, folded = _nonmanifold_drops(verts, faces)
        if not len(drop):
            break
        if not gone:  # the first round sees them all
            edges_fixed, folds = over, folded
        gone.append(numbers.select(face=drop))
        mask = np.ones(len(faces), bool)
        mask[drop] = False
        faces, numbers = _keep_faces(faces, numbers, mask)
    if gone:
        dropped = FileNumbers(numbers.vertex, np.concatenate([g.face for g in gone]),
                              None if numbers.line is None else np.concatenate([g.line for g in gone]),
                              numbers.base, numbers.unit)
        n = len(dropped.face)
        where = counted(edges_fixed, "non-manifold edges") + (
            f" and {counted(folds, 'edges')} where faces of two layers lie folded onto each other" if folds else "")
        changes["nonmanifold_faces"] = (n, f"dropped {counted(n, 'faces')} on {where}, the smallest sheets' first "
                                        f"({word} {dropped.faces(np.argsort(dropped.face))})")

    # 5: pinched vertices get a copy per fan (every edge has two faces at most now).
    old = faces
    verts, faces, split = split_nonmanifold(verts, faces)
    numbers = numbers.after_faces(len(verts), old, faces)
    if split["split_vertices"]:
        copies = np.arange(len(verts) - split["split_vertices"], len(verts))
        changes["pinched_vertices"] = (split["split_vertices"], f"split pinched vertices (sheets touching at a point) "
                                       f"into {split['split_vertices']} more copies (vertices "
                                       f"{numbers.vertices(copies)})")

    # 6: orientation of every orientable sheet.
    flip, conflicts, sheet = orientation(faces)
    nonorientable = np.unique(sheet[conflicts[:, 0]])
    flip &= ~np.isin(sheet, nonorientable)
    if flip.any():
        changes["reoriented_faces"] = (int(flip.sum()), f"flipped {counted(int(flip.sum()), 'faces')} to the winding of most of "
                                       f"their piece ({word} {numbers.faces(np.nonzero(flip)[0])})")
        faces = faces.copy()
        faces[flip] = faces[flip][:, ::-1]

    # 7: one piece.
    labels = np.unique(vertex_components(len(verts), faces)[faces[:, 0]], return_inverse=True)[1]
    area = np.bincount(labels, weights=face_areas(verts, faces))
    order = [int(k) for k in np.argsort(area, kind="stable")[::-1]]
    big = [k for k in order if area[k] >= PIECE_SHARE * area.sum()]
    bad_pieces = set(np.unique(labels[np.isin(sheet, nonorientable)]).tolist())
    why = {}
    for k in big:
        if k in bad_pieces:
            why[k] = "not orientable"
            continue
        try:
            check_wearable(verts, faces[labels == k], path)
        except InputError as err:
            why[k] = err.problem.split(":")[0]
    if piece is not None:
        index = 1 if piece == "largest" else int(piece)
        if not 1 <= index <= len(big):
            raise InputError(f"no piece {piece}: after the repairs the mesh has {len(big)} piece(s) of at least "
                             f"{100 * PIECE_SHARE:.0f}% of the area (numbered from the largest, 1)", path)
        keep = big[index - 1]
    else:
        good = [k for k in big if k not in why]
        if not good:
            left = diagnose(verts, faces, numbers)
            reasons = "; ".join(f"the piece of {100 * area[k] / area.sum():.0f}% of the area is {why[k]}" for k in big[:3])
            done = "; ".join(report.lines()) or "nothing"
            raise InputError(f"--repair found no wearable piece: {reasons}. Left after the repairs: {left.text()}. "
                             f"The repairs: {done}", path)
        keep = good[0]
    if len(order) > 1:
        others = labels != keep
        share = 100 * area[keep] / area.sum()
        dropped = f"{counted(len(order) - 1, 'other pieces')} ({counted(int(others.sum()), 'faces')}"
        changes["dropped_pieces"] = (len(order) - 1, f"kept the {'largest wearable ' if piece is None else ''}piece "
                                     f"with {share:.1f}% of the area ({int((~others).sum())} faces) and dropped "
                                     f"{dropped}; {word} {numbers.faces(np.nonzero(others)[0])})")
    faces, numbers = _keep_faces(faces, numbers, labels == keep)
    used = np.zeros(len(verts), bool)
    used[faces.ravel()] = True
    if not used.all():
        changes["unused_vertices"] = (int((~used).sum()), f"removed {counted(int((~used).sum()), 'vertices')} no face kept uses")
    remap = np.cumsum(used) - 1
    verts, faces = verts[used], remap[faces]
    numbers = numbers.select(vertex=np.nonzero(used)[0])
    report.after = diagnose(verts, faces, numbers)
    report.numbers = numbers
    if keep in why or not report.after.clean:
        raise InputError(f"--repair could not make a garment of it: the piece kept is "
                         f"{why.get(keep, 'still broken')}. Left after the repairs: {report.after.text()}. "
                         f"The repairs: {'; '.join(report.lines()) or 'nothing'}", path)
    return verts, faces, report


def _keep_faces(faces: np.ndarray, numbers: FileNumbers, mask: np.ndarray) -> tuple[np.ndarray, FileNumbers]:
    index = np.nonzero(mask)[0]
    return faces[index], numbers.select(face=index)


def _nonmanifold_drops(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, int, int]:
    """One round of the faces to drop so that no edge has more than two faces and no two faces of different
    sheets lie folded flat onto each other, smallest sheets first.

    Sheets are faces glued along two-face edges where they open by more than :data:`FOLDED` (two faces
    folded flat onto each other are two layers written over each other, such as two triangulations of one
    quad, not cloth). On an edge of more than two faces, or a folded one, a sheet whose area is the smallest
    on every such edge it touches (ties: the later in the file is the smaller, as an addition to what was
    there) drops its faces there, the later ones first and no more than leave two (one on a folded edge);
    the next round sees the sheets those drops have joined (once one triangulation of a quad goes, the other
    is glued to its neighbours). An edge of more than two faces all of one sheet keeps its first two; a fold
    within one sheet stays (a crease). Returns the sorted face ids, the numbers of edges of more than two
    faces and of folded edges."""
    edges, face_edge, count = unique_edges(faces)
    corner_edge = face_edge.reshape(-1)
    order = np.argsort(corner_edge, kind="stable")
    start = np.r_[0, np.cumsum(count)[:-1]]
    two = np.nonzero(count == 2)[0]
    h1, h2 = order[start[two]], order[start[two] + 1]  # corner c of face f: edge from c to c + 1
    folded = np.zeros(len(edges), bool)
    folded[two] = _opening(verts, faces, h1, h2) < np.radians(FOLDED)
    glued = ~folded[two]
    over = np.nonzero((count > 2) | folded)[0]
    if not len(over):
        return np.zeros(0, np.int64), 0, 0
    graph = sp.coo_matrix((np.ones(int(glued.sum())), (h1[glued] // 3, h2[glued] // 3)), shape=(len(faces),) * 2)
    sheet = connected_components(graph, directed=False)[1]
    area = np.bincount(sheet, weights=face_areas(verts, faces))
    first = np.full(len(area), len(faces))
    np.minimum.at(first, sheet, np.arange(len(faces)))
    rank = np.empty(len(area), np.int64)  # 0: the first to go
    rank[np.lexsort((-first, area))] = np.arange(len(area))
    on = np.isin(corner_edge, over)
    f, e = np.nonzero(on)[0] // 3, corner_edge[on]
    r = rank[sheet[f]]
    lowest = np.full(len(edges), len(area))
    highest = np.full(len(edges), -1)
    np.minimum.at(lowest, e, r)
    np.maximum.at(highest, e, r)
    mixed = lowest[e] != highest[e]  # incidences on edges of several sheets
    losing = np.ones(len(area), bool)  # a sheet is the smallest on every mixed edge it touches
    losing[r[mixed & (r != lowest[e])]] = False
    # Fewest first: on each edge, only as many of the losing sheet's faces as leave two (one where folded).
    surplus = np.where(folded, 1, count - 2)
    candidates = np.nonzero(mixed & losing[r])[0]
    drop = f[_first_per_edge(candidates[np.lexsort((-f[candidates], e[candidates]))], e, surplus)]
    # Edges of more than two faces, all of one sheet: keep the first two faces in the file.
    alone = np.nonzero(~mixed & ~folded[e])[0]
    gone = _first_per_edge(alone[np.lexsort((-f[alone], e[alone]))], e, surplus)
    drop = np.concatenate([drop, f[gone]])
    return np.unique(drop), int((count > 2).sum()), int(folded.sum())


def _opening(verts: np.ndarray, faces: np.ndarray, h1: np.ndarray, h2: np.ndarray) -> np.ndarray:
    """Angles (radians) between the two faces of edges seen along the edge, from the corners ``h1``, ``h2``
    (``3 f + c``: the edge runs from corner ``c`` of face ``f``): pi when flat, 0 when folded onto each other."""
    f1, c1 = h1 // 3, h1 % 3
    a, b = verts[faces[f1, c1]], verts[faces[f1, (c1 + 1) % 3]]
    axis = (b - a) / np.maximum(np.linalg.norm(b - a, axis=1, keepdims=True), 1e-300)
    tips = [verts[faces[h // 3, (h % 3 + 2) % 3]] - a for h in (h1, h2)]
    u, w = (t - np.einsum("ij,ij->i", t, axis)[:, None] * axis for t in tips)
    return np.arctan2(np.linalg.norm(np.cross(u, w), axis=1), np.einsum("ij,ij->i", u, w))


def _first_per_edge(order: np.ndarray, e: np.ndarray, how_many: np.ndarray) -> np.ndarray:
    """The incidences of ``order`` (sorted by edge) that come among the first ``how_many[edge]`` of their edge."""
    es = e[order]
    start = np.r_[0, np.nonzero(es[1:] != es[:-1])[0] + 1] if len(order) else np.zeros(0, np.int64)
    position = np.arange(len(order)) - np.repeat(start, np.diff(np.r_[start, len(order)]))
    return order[position < how_many[es]]
