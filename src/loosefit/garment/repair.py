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
4. on each edge of more than two faces keeps the two faces of the largest sheets (faces glued along
   two-face edges, by area) and drops the others: a fin, a pocket or a doubled panel goes, the garment's
   own surface stays;
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

from loosefit.errors import InputError
from loosefit.garment.diagnosis import DEGENERATE_AREA, Diagnosis, diagnose
from loosefit.garment.mesh_checks import face_areas, orientation, unique_edges, vertex_components
from loosefit.garment.mesh_file import FileNumbers
from loosefit.garment.seam_repair import slivers, split_nonmanifold, weld


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
        changes["merged_vertices"] = (merged, f"merged {merged} coincident vertices (panels written with their own "
                                              "seam vertices)")

    # 2-3: faces without area, then faces written twice.
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    bad = repeated | (face_areas(verts, faces) <= DEGENERATE_AREA * diag ** 2)
    if bad.any():
        changes["degenerate_faces"] = (int(bad.sum()), f"dropped {int(bad.sum())} degenerate faces (a repeated vertex "
                                       f"or no area: {word} {numbers.faces(np.nonzero(bad)[0])})")
    thin = ~bad & slivers(verts, faces)
    if thin.any():
        changes["sliver_faces"] = (int(thin.sum()), f"dropped {int(thin.sum())} sliver faces (height under 1e-3 of "
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
        changes["duplicate_faces"] = (n, f"merged {n} duplicate faces into the first of each ({word} "
                                      f"{numbers.faces(np.nonzero(~unique)[0])})")
    faces, numbers = _keep_faces(faces, numbers, unique)

    # 4: non-manifold edges keep the faces of their two largest sheets.
    dropped, edges_fixed, shown = 0, 0, ""
    while True:
        drop, over = _nonmanifold_drops(verts, faces)
        if not len(drop):
            break
        edges_fixed += over
        dropped += len(drop)
        shown = shown or numbers.faces(drop)  # the first round's: numbers of later rounds are the same file's
        mask = np.ones(len(faces), bool)
        mask[drop] = False
        faces, numbers = _keep_faces(faces, numbers, mask)
    if dropped:
        changes["nonmanifold_faces"] = (dropped, f"dropped {dropped} faces on {edges_fixed} non-manifold edges, those "
                                        f"of the smallest sheets on each ({word} {shown})")

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
        changes["reoriented_faces"] = (int(flip.sum()), f"flipped {int(flip.sum())} faces to the winding of most of "
                                       f"their piece ({word} {numbers.faces(np.nonzero(flip)[0])})")
        faces = faces.copy()
        faces[flip] = faces[flip][:, ::-1]

    # 7: one piece.
    labels = vertex_components(len(verts), faces)[faces[:, 0]]
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
        changes["dropped_pieces"] = (len(order) - 1, f"kept the {'largest wearable ' if piece is None else ''}piece "
                                     f"with {share:.1f}% of the area ({int((~others).sum())} faces) and dropped "
                                     f"{len(order) - 1} other pieces ({int(others.sum())} faces; {word} "
                                     f"{numbers.faces(np.nonzero(others)[0])})")
    faces, numbers = _keep_faces(faces, numbers, labels == keep)
    used = np.zeros(len(verts), bool)
    used[faces.ravel()] = True
    if not used.all():
        changes["unused_vertices"] = (int((~used).sum()), f"removed {int((~used).sum())} vertices no face kept uses")
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


def _nonmanifold_drops(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, int]:
    """The faces to drop so that no edge has more than two: on each such edge, all but the two whose sheets
    (faces glued along two-face edges) have the largest area, ties to the earlier face. Returns the sorted face
    ids and the number of non-manifold edges."""
    edges, face_edge, count = unique_edges(faces)
    over = np.nonzero(count > 2)[0]
    if not len(over):
        return np.zeros(0, np.int64), 0
    _, _, sheet = orientation(faces)
    sheet_area = np.bincount(sheet, weights=face_areas(verts, faces))[sheet]
    corner_edge = face_edge.reshape(-1)
    on = np.isin(corner_edge, over)
    f = np.nonzero(on)[0] // 3
    e = corner_edge[on]
    # Per edge: largest sheet first, then file order; everything after the second goes.
    order = np.lexsort((f, -sheet_area[f], e))
    e, f = e[order], f[order]
    start = np.r_[0, np.nonzero(e[1:] != e[:-1])[0] + 1]
    rank = np.arange(len(e)) - np.repeat(start, np.diff(np.r_[start, len(e)]))
    return np.unique(f[rank >= 2]), len(over)
