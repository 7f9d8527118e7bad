"""Importing a garment mesh from OBJ or PLY: validation and repair, unit and up-axis detection,
alignment to the body and removal of initial body penetration.

What is repaired silently (and counted in ``params["repairs"]``): duplicate vertices (merged),
degenerate faces (repeated vertex or zero area), duplicate faces, unreferenced vertices,
inconsistent face orientation (re-oriented), small loose pieces (under 2 % of the area: dropped).
What is an error (:class:`~loosefit.errors.InputError` naming the file): unreadable lines, face
indices out of range, NaN or infinite coordinates, an empty mesh, non-manifold edges or vertices,
a non-orientable surface, several large pieces.

Units: the largest bounding-box side below 5 is metres, below 500 centimetres, else millimetres.
Up axis: the mesh is tried Z-up as stored and Y-up turned to Z-up (``(x, y, z) -> (x, -z, y)``,
which also turns a +Z front into loosefit's -Y front); each is placed on the body (below) and the
better placement wins.
Placement: a garment rests on its top (waistband or shoulders), so the score of a placement is the
mean distance to the body of its top 4 cm plus a penalty for vertices inside the body. The mesh is
centred over the body's root joint and slid vertically (1 cm steps) to the best score, unless it
already scores within 5 mm of that where it is (a mesh made for this body keeps its position).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loosefit.body.base import BodyModel
from loosefit.errors import InputError
from loosefit.garment.fitting import orient_outward, push_out
from loosefit.garment.garment import Garment
from loosefit.garment.landmarks import measure_body
from loosefit.garment.mesh_checks import face_areas, face_components, mesh_report, nonmanifold_vertices, unique_edges
from loosefit.garment.obj_io import read_obj
from loosefit.garment.placement import place, to_z_up
from loosefit.garment.templates import CLEARANCE

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def read_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a PLY mesh through trimesh (no processing). Returns ``(verts, faces)``."""
    import trimesh

    try:
        mesh = trimesh.load(str(path), file_type="ply", process=False, force="mesh")
    except Exception as err:  # trimesh raises many types on malformed files
        raise InputError(f"unreadable PLY: {err}", path) from None
    verts = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    return verts, faces


def repair(verts: np.ndarray, faces: np.ndarray, path) -> tuple[np.ndarray, np.ndarray, dict]:
    """Validate and repair a triangle soup (see the module docstring). Returns the repaired
    ``(verts, faces)`` and counts of what was repaired."""
    if len(verts) == 0 or len(faces) == 0:
        raise InputError("the mesh has no vertices or no faces", path)
    bad = ~np.isfinite(verts).all(1)
    if bad.any():
        raise InputError(f"{bad.sum()} vertices have NaN or infinite coordinates (first: vertex {np.argmax(bad) + 1})", path)
    if faces.min() < 0 or faces.max() >= len(verts):
        raise InputError(f"a face index is out of range 1..{len(verts)}", path)
    repairs = {}
    diag = float(np.linalg.norm(verts.max(0) - verts.min(0)))
    # Merge vertices closer than a millionth of the size.
    key = np.round(verts / max(diag * 1e-6, 1e-12)).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    repairs["merged_vertices"] = int(len(verts) - len(first))
    order = np.argsort(first)  # keep the file's vertex order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    verts, faces = verts[first[order]], rank[inverse.reshape(-1)[faces]]
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    degenerate = repeated | (face_areas(verts, faces) <= (diag * 1e-7) ** 2)
    repairs["degenerate_faces"] = int(degenerate.sum())
    faces = faces[~degenerate]
    _, first = np.unique(np.sort(faces, 1), axis=0, return_index=True)
    repairs["duplicate_faces"] = int(len(faces) - len(first))
    faces = faces[np.sort(first)]
    if len(faces) == 0:
        raise InputError("every face is degenerate", path)
    edges, _, count = unique_edges(faces)
    if (count > 2).any():
        where = 0.5 * (verts[edges[count > 2, 0]] + verts[edges[count > 2, 1]])
        raise InputError(
            f"{int((count > 2).sum())} non-manifold edges (shared by more than 2 faces), near "
            f"{np.round(where[:3], 3).tolist()}",
            path,
        )
    pinch = nonmanifold_vertices(len(verts), faces)
    if len(pinch):
        raise InputError(
            f"{len(pinch)} non-manifold vertices (surface pinched to a point), near {np.round(verts[pinch[:3]], 3).tolist()}",
            path,
        )
    labels = face_components(faces)
    area = np.bincount(labels, weights=face_areas(verts, faces))
    if len(area[area > 0]) > 1:
        order = np.argsort(area)[::-1]
        if area[order[1:]].sum() > 0.02 * area.sum():
            raise InputError(
                f"{np.count_nonzero(area)} separate pieces; the second largest has "
                f"{100 * area[order[1]] / area.sum():.0f}% of the area (join them or keep one)",
                path,
            )
        repairs["dropped_pieces"] = int(np.count_nonzero(area) - 1)
        faces = faces[labels == order[0]]
    used = np.zeros(len(verts), bool)
    used[faces.reshape(-1)] = True
    repairs["unreferenced_vertices"] = int((~used).sum())
    remap = np.cumsum(used) - 1
    verts, faces = verts[used], remap[faces]
    faces, flipped = _orient(faces, path)
    repairs["reoriented_faces"] = flipped
    return verts, faces, repairs


def _orient(faces: np.ndarray, path) -> tuple[np.ndarray, int]:
    """Make face orientation consistent by a walk over edge neighbours; error if not orientable."""
    edges, face_edge, count = unique_edges(faces)
    nf = len(faces)
    # For each interior edge, its two faces and whether they traverse it in the same direction.
    he = face_edge.reshape(-1)
    order = np.argsort(he, kind="stable")
    starts = np.nonzero(np.r_[True, he[order][1:] != he[order][:-1]])[0]
    pairs = [(order[s], order[s + 1]) for s in starts if count[he[order[s]]] == 2]
    neighbours = [[] for _ in range(nf)]
    for h1, h2 in pairs:
        f1, c1, f2, c2 = h1 // 3, h1 % 3, h2 // 3, h2 % 3
        same = faces[f1, c1] == faces[f2, c2]  # both run a -> b: inconsistent
        neighbours[f1].append((f2, same))
        neighbours[f2].append((f1, same))
    flip = np.full(nf, -1)
    flip[0] = 0
    stack = [0]
    while stack:
        f = stack.pop()
        for g, same in neighbours[f]:
            want = flip[f] ^ int(same)
            if flip[g] < 0:
                flip[g] = want
                stack.append(g)
            elif flip[g] != want:
                raise InputError("the surface is not orientable (a Moebius-like strip)", path)
    out = faces.copy()
    out[flip == 1] = out[flip == 1][:, ::-1]
    return out, int((flip == 1).sum())


def _unit_scale(verts: np.ndarray, unit: str | None, path) -> tuple[float, str]:
    if unit is None:
        size = float((verts.max(0) - verts.min(0)).max())
        unit = "m" if size < 5 else "cm" if size < 500 else "mm"
    if unit not in UNITS:
        raise InputError(f"unknown unit {unit!r}; use one of {list(UNITS)}", path)
    return UNITS[unit], unit


def import_garment(
    path: str | Path, body: BodyModel, unit: str | None = None, up: str | None = None, clearance: float = CLEARANCE
) -> Garment:
    """Import a garment mesh (.obj or .ply) and fit it to ``body``'s rest pose.

    Args:
        path: the mesh file.
        body: the body it will be simulated on.
        unit: ``"m"``, ``"cm"`` or ``"mm"``; detected from the size when ``None``.
        up: ``"z"`` or ``"y"``; detected by fit to the body when ``None``.
        clearance: vertices and edge midpoints closer to the body than this (metres) are pushed out.

    Returns:
        A :class:`Garment` of kind ``"imported"``; ``params`` records the unit, up axis, offset
        and repairs. The vertices within 3 cm of the garment's top are pinned.

    Raises:
        InputError: the file is unreadable or broken beyond safe repair (see the module docstring).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", path)
    suffix = path.suffix.lower()
    if suffix == ".obj":
        verts, faces = read_obj(path)
    elif suffix == ".ply":
        verts, faces = read_ply(path)
    else:
        raise InputError(f"unsupported garment format {suffix!r}; use .obj or .ply", path)
    verts, faces, repairs = repair(verts, faces, path)
    scale, unit = _unit_scale(verts, unit, path)
    verts = verts * scale
    lm = measure_body(body)
    if up is not None and up not in ("y", "z"):
        raise InputError(f"up axis must be 'y' or 'z', got {up!r}", path)
    placement = place(verts, faces, lm, path, up)
    verts = to_z_up(verts, placement.up) + placement.offset
    faces = orient_outward(verts, faces, lm.sdf)
    verts = push_out(verts, faces, lm.sdf, clearance)
    report = mesh_report(verts, faces)
    if not report.ok:
        raise InputError(f"mesh is still broken after repair: {report}", path)
    pinned = verts[:, 2] > verts[:, 2].max() - 0.03
    params = {"source": str(path), "unit": unit, **placement.as_dict(), "repairs": repairs}
    return Garment(verts=verts, faces=faces, pinned=pinned, kind="imported", params=params, name=path.stem)

