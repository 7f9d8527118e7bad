"""Importing a garment mesh from OBJ or PLY: validation and repair, unit and up-axis detection,
alignment to the body and removal of initial body penetration.

What is repaired (and counted in ``params["repairs"]``): duplicated vertices (welded within
:data:`WELD` of the size: seams written as separate panels), degenerate faces (repeated vertex or
zero area), sliver faces (height under 1e-3 of the longest edge), duplicate faces, non-manifold
edges where three or more panels meet and pinched vertices (split into manifold fans,
:mod:`loosefit.garment.seam_repair`), unreferenced vertices, inconsistent face orientation
(re-oriented to the orientation most of each piece's faces have), small loose pieces (under 2 % of the
area: dropped, such as a flap cut off by a split seam).
Several pieces (a crop top and a skirt): ``piece`` (``--piece largest|N``) keeps one; without it they are
one garment when each piece could be worn by itself (:func:`check_wearable`) and is attached once placed
(:func:`check_attached`: its top no lower than the lowest waistband, at most 6 cm from the body), each
pinned at its own top.
What is an error (:class:`~loosefit.errors.InputError` naming the file): unreadable lines, face
indices out of range, NaN or infinite coordinates, an empty mesh, a surface these repairs leave broken
(non-manifold edges left, a non-orientable piece: the message counts what is wrong with the file,
:mod:`loosefit.garment.diagnosis`, naming vertices and faces as the file numbers them, and points to
``--repair``, :mod:`loosefit.garment.repair`, which drops what breaks it),
several pieces where one is not wearable or hangs free (the message names ``--piece``), a mesh too small
to be worn (:func:`check_wearable`: fewer than two openings, or a largest opening of fewer than 8
vertices), normals pointing inwards, no plausible placement on the body, a push out of the body over
:func:`max_push`.

Units: each of metres, centimetres and millimetres that makes the garment's largest side
between 0.15 and 2.5 m is tried (at most two of them can), and the better placement wins; a unit that
makes it smaller or larger (given with ``unit``, or when none fits) is refused with the sizes tried.

The shape is kept: placement is rigid (an axis swap and a translation) plus the unit's uniform scale. The
only other change is the push out of the body to the clearance
(:func:`~loosefit.garment.fitting.push_out_bounded`: each vertex moves by at most its own depth short of the
clearance plus 1 mm, nothing is smoothed), reported in ``params["pushed_out"]`` (largest and mean move in mm,
share of vertices moved, and moved more than 5 mm). A 6 mm dent at the hips moves 12-14 mm (6 mm in, 5 mm
clearance, its edges' midpoints a little deeper), where the earlier push-and-relax moved it 64 mm. A push over
:func:`max_push` (20 mm at the 5 mm clearance) is refused: the placement tolerates points up to 1 cm inside,
so deeper cloth is a garment cut for another body, not a dent. Measured on templates made for other Anny
shapes (seed 0, 3 cm edges) imported onto the default body: a skirt or dress for a taller body, a long shirt
or dress for a thin one need no push, a skirt for a thin one 5.4 mm, a long shirt for a taller body would
move 23 mm and is refused.

A garment made for another body (``fit=True``, or ``fit=None`` when the direct placement or the push is
refused) is fitted as a garment tool does it: :mod:`loosefit.garment.body_fit` finds the Anny shape it fits
(over all six keys), places it there and drapes it onto the body with Blender cloth while the body changes shape.
A push after that drape over :func:`max_push` is refused saying how the fit came about (asked, or after the direct
placement's refusal) and naming the shape found as a ``--shape`` to import and simulate the garment on.

Inside out: a garment whose normals point inwards (:func:`outward_flux` negative, its faces consistently
oriented as most of the file's faces are) is refused.
Up axis, attachment (waistband, strapless top, shoulders, straps) and placement:
:mod:`loosefit.garment.placement`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from loosefit.body.base import BodyModel
from loosefit.errors import InputError
from loosefit.garment.fitting import PUSH_MARGIN, push_out_bounded
from loosefit.garment.garment import Garment, shape_record
from loosefit.garment.landmarks import measure_body
from loosefit.garment.diagnosis import diagnose
from loosefit.garment.mesh_checks import (BoundaryError, boundary_loops, face_areas, face_components, mesh_report,
                                          orientation, unique_edges, vertex_components)
from loosefit.garment.mesh_file import FileNumbers, read_mesh_file, read_ply  # noqa: F401 - read_ply: its old home
from loosefit.garment.placement import MAX_TOP_GAP, place, to_z_up
from loosefit.garment.seam_repair import slivers, split_nonmanifold, weld
from loosefit.garment.templates import CLEARANCE

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: Pieces under this share of the area are debris and dropped (a flap cut off by a split seam).
PIECE_SHARE = 0.02
#: Vertices closer than this fraction of the bounding-box diagonal are welded (0.17 mm on a 1.7 m dress).
WELD = 1e-4
#: Plausible garment sizes (largest bounding-box side), m: they pick the file's unit.
SIZE_RANGE = (0.15, 2.5)
#: A garment is worn: the body passes through it, so its surface is at least a tube, open at the top
#: (waist or neck) and at the hem: two boundary loops or more (a disc, a single triangle or a closed
#: surface cannot be put on).
MIN_OPENINGS = 2
#: The hem goes all around the body, which placement reads in eight 45-degree sectors
#: (:mod:`loosefit.garment.placement`): a largest opening of fewer vertices cannot follow the body.
MIN_HEM_VERTICES = 8


def auto_repair(verts: np.ndarray, faces: np.ndarray, path, piece: str | int | None = None, several: bool = False,
                numbers: FileNumbers | None = None, welded: bool = False):
    """Validate and repair a triangle soup (see the module docstring). Returns the repaired
    ``(verts, faces)``, counts of what was repaired and the repaired mesh's
    :class:`~loosefit.garment.mesh_file.FileNumbers` (``numbers``: the file's, default as given).

    ``piece``: ``"largest"`` or ``N`` (1 the largest) keeps that piece only; ``None`` keeps every piece of at
    least :data:`PIECE_SHARE` of the area when ``several``, else refuses a file with more than one.
    ``welded``: the vertices were welded already (:func:`loosefit.garment.repair.repair_mesh`; welding again
    could join the copies of a vertex it split).

    A surface these repairs leave broken (non-manifold edges left after pairing their faces, a non-orientable
    piece) is refused with :func:`~loosefit.garment.diagnosis.diagnose`'s counts of the file, in its own
    numbers."""
    if len(verts) == 0 or len(faces) == 0:
        raise InputError("the mesh has no vertices or no faces", path)
    numbers = numbers or FileNumbers.identity(len(verts), len(faces), base=1)
    bad = ~np.isfinite(verts).all(1)
    if bad.any():
        raise InputError(f"{bad.sum()} vertices have NaN or infinite coordinates (first: vertex "
                         f"{numbers.vertices([np.argmax(bad)], 1)})", path)
    if faces.min() < 0 or faces.max() >= len(verts):
        raise InputError(f"a face index is out of range {numbers.base}..{len(verts) - 1 + numbers.base}", path)
    repairs = {}
    diag = float(np.linalg.norm(verts.max(0) - verts.min(0)))
    if welded:
        repairs["merged_vertices"] = 0
    else:
        verts, faces, repairs["merged_vertices"], kept = weld(verts, faces, WELD * diag, return_kept=True)
        numbers = numbers.select(vertex=kept)
    welded_mesh = (verts, faces, numbers)  # what the diagnosis of a refusal describes
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    degenerate = repeated | (face_areas(verts, faces) <= (diag * 1e-7) ** 2)
    repairs["degenerate_faces"] = int(degenerate.sum())
    thin = ~degenerate & slivers(verts, faces)
    repairs["sliver_faces"] = int(thin.sum())
    kept = np.nonzero(~(degenerate | thin))[0]
    faces, numbers = faces[kept], numbers.select(face=kept)
    _, first = np.unique(np.sort(faces, 1), axis=0, return_index=True)
    repairs["duplicate_faces"] = int(len(faces) - len(first))
    first = np.sort(first)
    faces, numbers = faces[first], numbers.select(face=first)
    if len(faces) == 0:
        raise InputError("every face is degenerate", path)
    old = faces
    verts, faces, split = split_nonmanifold(verts, faces)
    numbers = numbers.after_faces(len(verts), old, faces)
    repairs.update(split)
    labels = face_components(faces)
    area = np.bincount(labels, weights=face_areas(verts, faces))
    order = [int(k) for k in np.argsort(area)[::-1] if area[k] > 0]
    big = [k for k in order if area[k] > PIECE_SHARE * area.sum()]
    if piece is not None:
        index = 1 if piece == "largest" else int(piece)
        if not 1 <= index <= len(big):
            raise InputError(f"no piece {piece}: the file has {len(big)} piece(s) of at least "
                             f"{100 * PIECE_SHARE:.0f}% of the area (numbered from the largest, 1)", path)
        keep = [big[index - 1]]
    elif len(big) > 1 and not several:
        raise InputError(_pieces_problem(area, order, split), path)
    else:
        keep = big
    repairs["dropped_pieces"] = int(len(order) - len(keep))
    kept = np.nonzero(np.isin(labels, keep))[0]
    faces, numbers = faces[kept], numbers.select(face=kept)
    used = np.zeros(len(verts), bool)
    used[faces.reshape(-1)] = True
    repairs["unreferenced_vertices"] = int((~used).sum())
    remap = np.cumsum(used) - 1
    verts, faces = verts[used], remap[faces]
    numbers = numbers.select(vertex=np.nonzero(used)[0])
    edges, _, count = unique_edges(faces)
    if (count > 2).any():  # faces of a seam that pairing left on one vertex pair: the fans around it join up
        raise topology_error(f"{int((count > 2).sum())} non-manifold edges are left after gluing the faces of each "
                             f"seam in pairs (vertices {numbers.edges(edges[count > 2])})", path, welded_mesh)
    flip, conflicts, _ = orientation(faces)
    if len(conflicts):
        paired = ", once the faces of each non-manifold seam are glued in pairs" if split["nonmanifold_edges"] else ""
        raise topology_error(f"the surface is not orientable (a Moebius-like strip) where {numbers.unit}s "
                             f"{numbers.faces(conflicts[:, 0])} meet their neighbours{paired}", path, welded_mesh)
    faces = faces.copy()
    faces[flip] = faces[flip][:, ::-1]
    repairs["reoriented_faces"] = int(flip.sum())
    return verts, faces, repairs, numbers


def topology_error(problem: str, path, file_mesh) -> InputError:
    """The refusal of a surface the import cannot use: ``problem`` and the counts of what is wrong with the
    file (``file_mesh``: its welded ``(verts, faces, numbers)``), with the way out."""
    verts, faces, numbers = file_mesh
    counting = "from 1" if numbers.base == 1 else "from 0"
    d = diagnose(verts, faces, numbers)
    if d.nonmanifold_edges or d.duplicate_faces or d.degenerate_faces or d.pinched_vertices or d.pieces > 1:
        way = "`--repair` drops the faces that make it so, keeps the largest wearable piece and says what it changed"
    else:  # nothing to drop: the surface itself has one side
        way = "A garment has an inside and an outside, so the file needs mending where it was made"
    return InputError(f"{problem}. The file has (welded; numbers as in the file, {counting}): {d.text()}. {way}",
                      path)


def _pieces_problem(area: np.ndarray, order: list[int], split: dict) -> str:
    return (f"{len(order)} separate pieces; the second largest has {100 * area[order[1]] / area.sum():.0f}% of the "
            f"area (join them, or keep one with --piece largest|N)"
            + (f", after splitting {split['nonmanifold_edges']} non-manifold edges" if split["nonmanifold_edges"] else ""))


def check_wearable(verts: np.ndarray, faces: np.ndarray, path, numbers: FileNumbers | None = None) -> None:
    """Refuse a repaired mesh too small to be a garment: fewer than :data:`MIN_OPENINGS` openings
    (boundary loops), or a largest opening of fewer than :data:`MIN_HEM_VERTICES` vertices. ``numbers``: the
    file's numbering of ``verts``, to name a vertex as the file does."""
    try:
        loops = boundary_loops(faces)
    except BoundaryError as err:  # repair leaves manifold boundaries; say so if one is not
        where = (f"vertex {numbers.vertices([err.vertex], 1)} of the file" if numbers is not None
                 else f"vertex {err.vertex}")
        raise InputError(f"the mesh's openings are not simple loops: more or fewer than two boundary edges meet at "
                         f"{where}", path) from None
    size = f"{len(verts)} vertices, {len(faces)} faces"
    if len(loops) < MIN_OPENINGS:
        raise InputError(
            f"not a garment: {size} with {len(loops)} opening(s); a garment goes around the body, so it is at "
            f"least a tube open at the top and at the hem ({MIN_OPENINGS} boundary loops)", path)
    hem = max(len(loop) for loop in loops)
    if hem < MIN_HEM_VERTICES:
        raise InputError(
            f"too coarse to be a garment: {size}, its largest opening has {hem} vertices; an opening that goes "
            f"around the body needs at least {MIN_HEM_VERTICES} (one in each 45-degree sector)", path)


def outward_flux(verts: np.ndarray, faces: np.ndarray) -> float:
    """``sum_f A_f n_f . (c_f - c)`` over the faces (area ``A_f``, unit normal ``n_f``, centroid ``c_f``) about
    the surface's centroid ``c``, m^3. On a closed surface it is three times the enclosed volume, whatever
    ``c``; on a tube open at both ends (a garment) the missing end caps take part of that, and what is left
    is still positive when the normals point outward (a cylinder: 2/3 of the volume; a cone's frustum
    too), negative when they point in."""
    tri = verts[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # 2 A n
    centroid = tri.mean(1)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    c = (centroid * area[:, None]).sum(0) / max(area.sum(), 1e-12)
    return float(0.5 * np.einsum("ij,ij->", cross, centroid - c))


def check_outward(verts: np.ndarray, faces: np.ndarray, path) -> None:
    """Refuse a garment whose normals point inwards (:func:`outward_flux` negative): inside out, or its
    faces wound the other way. Its faces are consistently oriented already (:func:`auto_repair`)."""
    labels = face_components(faces)
    for k in np.unique(labels):
        if outward_flux(verts, faces[labels == k]) < 0:
            which = "" if labels.max() == 0 else f" (piece of {int((labels == k).sum())} faces)"
            raise InputError(f"the garment is inside out{which}: its faces' normals point inwards, towards the body; "
                             "wind the faces the other way (counter-clockwise seen from outside) or turn it right side "
                             "out", path)


def _units(verts: np.ndarray, unit: str | None, path) -> list[str]:
    """The units to try: ``unit`` when given, else those giving a garment size (largest
    bounding-box side) between :data:`SIZE_RANGE` metres, else the closest one."""
    if unit is not None and unit not in UNITS:
        raise InputError(f"unknown unit {unit!r}; use one of {list(UNITS)}", path)
    size = float((verts.max(0) - verts.min(0)).max())
    lo, hi = SIZE_RANGE
    fits = [u for u, s in UNITS.items() if lo <= size * s <= hi and unit in (None, u)]
    if not fits:
        sizes = {u: _length(size * s) for u, s in UNITS.items()}
        tried = ", ".join(f"{sizes[u]} in {u}" for u in ([unit] if unit else UNITS))
        others = "" if unit is None else " (in the other units: " + ", ".join(
            f"{v} in {u}" for u, v in sizes.items() if u != unit) + ")"
        raise InputError(f"no unit gives a garment's size: its largest side is {tried}, and a garment's is "
                         f"between {lo} and {hi} m{others}", path)
    return fits


def _length(metres: float) -> str:
    """A length for people: mm below a centimetre, cm below a metre, else m."""
    if metres < 0.01:
        return f"{metres * 1e3:.3g} mm"
    return f"{metres * 1e2:.3g} cm" if metres < 1.0 else f"{metres:.3g} m"


def import_garment(
    path: str | Path, body: BodyModel, unit: str | None = None, up: str | None = None, clearance: float = CLEARANCE,
    fit: bool | None = False, fit_params=None, fit_search=None, piece: str | int | None = None,
    repair: bool = False,
) -> Garment:
    """Import a garment mesh (.obj or .ply) and fit it to ``body``'s rest pose.

    Args:
        path: the mesh file.
        body: the body it will be simulated on.
        unit: ``"m"``, ``"cm"`` or ``"mm"``; detected from the size when ``None``.
        up: ``"z"`` or ``"y"``; detected by fit to the body when ``None``.
        clearance: vertices and edge midpoints closer to the body than this (metres) are pushed out.
        fit: ``True``: fit it as a garment made for another body (:mod:`loosefit.garment.body_fit`: find
            the Anny shape it was made for, place it there, drape it onto ``body`` with Blender cloth);
            ``None``: only when the direct placement is refused; ``False``: never.
        fit_params: simulation parameters of the fit's drape (defaults when ``None``).
        fit_search: a :class:`loosefit.garment.body_fit.Search` (defaults when ``None``).
        piece: ``"largest"`` or ``N`` (1 is the largest): keep that connected piece only. ``None``: keep every
            piece as one garment when each is attached to the body (:func:`check_attached`: a crop top and a
            skirt), else refuse.
        repair: first repair the file by dropping what breaks it (:func:`loosefit.garment.repair.repair_mesh`:
            faces on non-manifold edges, loose pieces; one piece kept, the largest wearable one or ``piece``).

    Returns:
        A :class:`Garment` of kind ``"imported"``; ``params`` records the unit, the
        placement (:meth:`loosefit.garment.placement.Placement.as_dict`: up axis, attachment,
        offset, top height, top gap, inside fraction; on the body found when fitted), the repairs, the push
        out of the body and, when fitted, ``params["fit"]``: why, the shape found, the drape and the share
        of vertices more than 2 mm inside the body. With ``repair``, ``params["repair"]``: what it changed
        (``counts``, ``changes``: a line each) and the counts of what was wrong with the file (``file``). The
        vertices within 3 cm of the garment's top are pinned.

    Raises:
        InputError: the file is unreadable or broken beyond safe repair, or no placement on the
            body is plausible (see the module docstring).
    """
    path = Path(path)
    verts, faces, numbers = read_mesh_file(path)
    forced = None
    if repair:
        from loosefit.garment.repair import repair_mesh

        verts, faces, forced = repair_mesh(verts, faces, numbers, piece=piece, path=path)
        numbers, piece = forced.numbers, None  # the piece is chosen
    verts, faces, repairs, numbers = auto_repair(verts, faces, path, piece, several=True, numbers=numbers,
                                                 welded=forced is not None)
    pieces = vertex_components(len(verts), faces)
    if pieces.max() > 0:  # several pieces are one garment only where each could be worn
        labels = pieces[faces[:, 0]]
        area = np.bincount(labels, weights=face_areas(verts, faces))
        for k in range(len(area)):
            try:
                check_wearable(verts, faces[labels == k], path, numbers)
            except InputError as err:
                raise InputError(f"{_pieces_problem(area, list(np.argsort(area)[::-1]), repairs)}; a piece with "
                                 f"{100 * area[k] / area.sum():.0f}% of the area is no garment by itself: "
                                 f"{err.problem}", path) from None
    check_wearable(verts, faces, path, numbers)
    check_outward(verts, faces, path)
    units = _units(verts, unit, path)
    lm = measure_body(body)
    if up is not None and up not in ("y", "z"):
        raise InputError(f"up axis must be 'y' or 'z', got {up!r}", path)
    refused, fitted = None, None
    if fit is not True:
        try:
            placement, unit = _place(verts, faces, units, lm, path, up)
            check_attached(to_z_up(verts * UNITS[unit], placement.up) + placement.offset, faces, pieces, lm, path)
            pushed_verts, moved = _push(to_z_up(verts * UNITS[unit], placement.up) + placement.offset, faces, lm,
                                        clearance, path, "placed on this body",
                                        " (made for another body? --fit drapes it from the body it fits)")
        except InputError as err:
            if fit is False or not _has_shapes(body) or DETACHED in err.problem.split(":")[0]:
                raise
            refused = err
    if fit is True or refused is not None:
        from loosefit.garment.body_fit import Search, fit_to_body

        try:
            fitted, shape_fit, _, info = fit_to_body(
                {u: verts * UNITS[u] for u in units}, faces, body, path, up, params=fit_params,
                search=fit_search or Search(), pieces=pieces,
                check=lambda placed, lm_found: check_attached(placed, faces, pieces, lm_found, path))
        except InputError as err:
            if refused is None or DETACHED in err.problem.split(":")[0]:
                raise
            raise InputError(f"{refused.problem}; fitted as a garment made for another body: {err.problem}",
                             path) from None
        placement, unit = shape_fit.placement, shape_fit.unit
        info["why"] = "asked" if refused is None else refused.problem.split(";")[0].split(" (")[0]
        pushed_verts, moved = _push(fitted, faces, lm, clearance, path, *_drape_refusal(shape_fit.shape, refused))
    verts = pushed_verts
    pushed = {"max_mm": round(1e3 * float(moved.max()), 2),
              "mean_mm": round(1e3 * float(moved[moved > 0].mean()) if (moved > 0).any() else 0.0, 2),
              "moved_percent": round(100.0 * float((moved > 0).mean()), 2),
              "over_5mm_percent": round(100.0 * float((moved > 0.005).mean()), 2)}
    report = mesh_report(verts, faces)
    if report.num_components != pieces.max() + 1 or not dataclasses.replace(report, num_components=1).ok:
        raise InputError(f"mesh is still broken after repair: {diagnose(verts, faces, numbers).text()}", path)
    pinned = top_pins(verts, pieces)
    params = {"source": str(path), "unit": unit, **placement.as_dict(), "repairs": repairs, "pushed_out": pushed,
              "pieces": int(pieces.max() + 1)}
    if forced is not None:
        params["repair"] = {"counts": forced.counts(), "changes": forced.lines(), "file": forced.before.counts()}
    if fitted is not None:
        from loosefit.garment.body_fit import inside_percent

        info["inside_percent"] = round(inside_percent(verts, lm.sdf), 2)
        params["fit"] = info
    return Garment(verts=verts, faces=faces, pinned=pinned, kind="imported", params=params, name=path.stem,
                   body_shape=shape_record(getattr(body, "shape", None)))


#: Depth inside the body that the placement tolerates in its points (it counts only deeper ones), m.
TOLERATED_DEPTH = 0.01


def max_push(clearance: float) -> float:
    """The largest push out of the body accepted, m: a vertex the placement tolerates
    (:data:`TOLERATED_DEPTH` inside) is moved to ``clearance`` outside, plus the pusher's margin, with the
    same again for an edge midpoint deeper than its ends on the curved body: a quarter more. 20 mm at the
    5 mm clearance. Deeper cloth is not a dent but a garment cut for another body."""
    return 1.25 * (TOLERATED_DEPTH + clearance + PUSH_MARGIN)


#: The start of the refusal of a piece that hangs free (not a matter of the body's shape: never fitted).
DETACHED = "separate pieces, not all attached"


def top_pins(verts: np.ndarray, pieces: np.ndarray, depth: float = 0.03) -> np.ndarray:
    """``(V,)`` bool: the vertices within ``depth`` m of their own piece's top (``pieces (V,)`` labels)."""
    tops = np.full(pieces.max() + 1, -np.inf)
    np.maximum.at(tops, pieces, verts[:, 2])
    return verts[:, 2] > tops[pieces] - depth


def check_attached(verts: np.ndarray, faces: np.ndarray, pieces: np.ndarray, lm, path) -> None:
    """Refuse a garment of several pieces (``pieces (V,)`` labels) placed at ``verts (V, 3)`` where a piece
    hangs free: its top below the lowest waistband (18 cm under the waist), or its top 4 cm more than
    :data:`~loosefit.garment.placement.MAX_TOP_GAP` from the body on average. Each piece is pinned at its
    top, so a piece that is not attached there would hang from nothing."""
    count = int(pieces.max() + 1)
    if count == 1:
        return
    area = np.bincount(pieces[faces[:, 0]], weights=face_areas(verts, faces), minlength=count)
    for k in np.argsort(area)[::-1]:
        mine = verts[pieces == k]
        top = mine[:, 2].max()
        gap = float(np.abs(lm.sdf.query(mine[mine[:, 2] > top - 0.04])).mean())
        if top < lm.waist_z - 0.18 or gap > MAX_TOP_GAP:
            raise InputError(
                f"{count} {DETACHED}: a piece with {100 * area[k] / area.sum():.0f}% of the area has its top at "
                f"{top:.2f} m, {100 * gap:.1f} cm from the body (a piece hangs from its top: at most "
                f"{100 * MAX_TOP_GAP:.0f} cm away, and no lower than {lm.waist_z - 0.18:.2f} m); join them, or keep "
                f"one with --piece largest|N", path)


def _push(verts, faces, lm, clearance: float, path, where: str, hint: str = ""):
    """:func:`~loosefit.garment.fitting.push_out_bounded`, refused over :func:`max_push` (the refusal says
    ``where`` first and ends with ``hint``). Returns ``(verts, moved)``."""
    pushed, moved = push_out_bounded(verts, faces, lm.sdf, clearance)
    limit = max_push(clearance)
    if moved.max() > limit:
        raise InputError(f"{where}, {int((moved > limit).sum())} vertices are too deep inside the body: pushing them "
                         f"out would move them up to {1e3 * moved.max():.0f} mm, over the {1e3 * limit:.0f} mm "
                         f"limit{hint}", path)
    return pushed, moved


def _drape_refusal(shape, refused: InputError | None) -> tuple[str, str]:
    """What a refusal after a fit's drape says first and last (:func:`_push`'s ``where`` and ``hint``): how the
    fit came about (asked with --fit, or because the direct placement was refused: ``refused``), the body it was
    draped from, and the way out: that body's ``--shape`` (the garment sits on it as made, so it is imported there
    without a drape)."""
    from loosefit.garment.body_fit import shape_option

    option = shape_option(shape)
    found = f"the body it fits best ({option})"
    if refused is None:
        where = f"with --fit, after the drape from {found} onto this one"
    else:
        where = (f"{refused.problem.split(';')[0].split(' (')[0]}; fitted instead as a garment made for another "
                 f"body, after the drape from {found} onto this one")
    return where, (f". The garment was made for a body like that one: import it onto that body, "
                   f"`loosefit garment import FILE {option}`, and simulate with the same --shape")


def _has_shapes(body) -> bool:
    """Whether ``body`` has the shape keys a fit searches (Anny)."""
    from loosefit.body.anny_body import AnnyBody

    return isinstance(body, AnnyBody)


def _place(verts: np.ndarray, faces: np.ndarray, units: list[str], lm, path, up: str | None):
    """The best placement over the plausible ``units``: ``(Placement, unit)``; refused as :func:`place` is."""
    fits, refusals = [], []
    for unit in units:
        try:
            fits.append((place(verts * UNITS[unit], faces, lm, path, up), unit))
        except InputError as err:
            refusals.append(f"as {unit}: {err.problem}" if len(units) > 1 else err.problem)
    if not fits:
        raise InputError("; ".join(refusals), path)
    return min(fits, key=lambda fit: fit[0].score)
