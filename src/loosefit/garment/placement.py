"""Placing an imported garment on the body: up axis, attachment type, height, and refusal.

A garment hangs from one attachment: a **waistband** (skirt, trousers), a **strapless bodice**
(the top edge around the chest), **shoulders** or **straps**. The attachment is read from the
geometry of the garment's top 3 cm: where it goes all around the garment's axis (all eight 45
degree sectors) or is near-vertical cloth (area-weighted mean ``|n_z| <= 0.5``: a strapless top
edge higher at the front than at the back) it is a ring, a waistband or a strapless chest line;
otherwise cloth lies over the top and rests on the shoulders (the top 10 cm in one piece) or on
straps (in two pieces). Measured ``|n_z|`` on the templates: 0.84-0.90 for shoulders and straps,
0.51-0.55 for 1.5 cm straps, 0.19 for a strapless top, 0.44-0.71 for skirts (flare 0 to 45 degrees,
all rings by the sector rule). Where the type read finds no plausible placement, the other
(ring or hanging) is tried too.

Up axis: a garment is a tube open at its hem, so the plane of its longest boundary loop (the hem)
is horizontal. Its normal picks the file's up axis among Y and Z (the file's own sign is kept: a
Y-up file has +Y up). Where the loops do not decide (no loop, or a normal more than 45 degrees
from both axes) both axes are tried and the better fit wins.

Height: each attachment type has a window of body heights where its top may lie, from the
body's landmarks (:mod:`loosefit.garment.landmarks`):

* ring (waistband or strapless): from 18 cm below the natural waist to 15 cm above the armpits;
* shoulders / straps: from 3 cm above the armpits to 12 cm above the neck joint.

Within the window the garment is slid vertically in 1 cm steps and front-back by -2, 0 and 2 cm
(scored on 400 points), then around the best in 1 cm, 5 mm and 2 mm steps both ways (all
:data:`SAMPLES` points). The score is :func:`fit_score`: how uneven the gap to the body is over the garment's upper band (a
garment made for a body keeps an even gap there; moved up or down, one part comes closer and
another moves away) plus penalties for cloth inside the body. The band is the top 4 cm for rings
(a waistband hangs from its edge) and the top 10 cm for shoulders and straps. The mesh's
left-right centre is put on the body's midline. Where the file's own position is in the window
and scores within 3 mm of the best one, it is kept (a mesh made for this body keeps its place).
Measured on the templates written Y-up about the pelvis or Z-up from another origin, in m, cm or
mm (tests/garment/test_importer.py): dresses with sleeves, straps or a strapless top, long
shirts, jumpsuits and natural-waist skirts land within 5 mm of where they were made (flared at 40
degrees: 2 cm); dresses made for a taller, shorter, heavier or thinner Anny land within 1.4 cm of
the same height above the waist or neck. Known limit: a waistband ring alone says little about
its height, so a low-rise skirt (15 cm under the waist) lands 5 cm high and a high-waisted one
(8 cm over it) 13 cm low, around the natural waist.

Refusal (:class:`~loosefit.errors.InputError` naming the file, the axes, attachment and heights
tried): no placement in the window has less than :data:`MAX_INSIDE` of its points more than 1 cm
inside the body, or the best one leaves a mean gap over the top band above :data:`MAX_TOP_GAP`
(a garment much wider than the body, or one whose top is not where it could hang).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loosefit.errors import InputError
from loosefit.garment.landmarks import BodyLandmarks
from loosefit.garment.mesh_checks import boundary_loops, face_areas, face_components

#: A placement is refused when more than this fraction of garment points is over 1 cm inside the body.
MAX_INSIDE = 0.03
#: A placement is refused when the mean gap of the garment's top 4 cm to the body exceeds this, m.
MAX_TOP_GAP = 0.06
#: Depth of the upper band scored for the fit of a waistband or strapless top, m.
RING_BAND = 0.04
#: Depth of the upper band scored for the fit of a garment on shoulders or straps, m.
HANGING_BAND = 0.10
#: Points scored per placement (a subset of the vertices, spread over the vertex order).
SAMPLES = 1500
#: With a hint of the top's height, the search covers this much above and below it, m.
HINT_RANGE = 0.05


@dataclass
class Placement:
    """Where a garment goes on the body.

    Attributes:
        up: the file's up axis, ``"y"`` or ``"z"``.
        attachment: ``"waistband"``, ``"strapless"``, ``"shoulders"`` or ``"straps"``.
        offset: ``(3,)`` translation added to the Z-up vertices, m.
        top_z: height of the garment's top once placed, m.
        score: :func:`fit_score` of the placement, m.
        top_gap: mean distance of the top 4 cm to the body, m.
        inside: fraction of scored points more than 1 cm inside the body.
    """

    up: str
    attachment: str
    offset: np.ndarray
    top_z: float
    score: float
    top_gap: float
    inside: float

    def as_dict(self) -> dict:
        return {
            "up": self.up,
            "attachment": self.attachment,
            "offset": np.round(self.offset, 6).tolist(),
            "top_z": round(self.top_z, 4),
            "top_gap": round(self.top_gap, 4),
            "inside": round(self.inside, 4),
        }


def to_z_up(verts: np.ndarray, up: str) -> np.ndarray:
    """``(V, 3)`` vertices of a file with ``up`` (``"y"`` or ``"z"``) in loosefit's Z-up frame:
    ``(x, y, z) -> (x, -z, y)`` for Y-up, which also turns a +Z front into loosefit's -Y front."""
    return verts if up == "z" else np.stack([verts[:, 0], -verts[:, 2], verts[:, 1]], 1)


def detect_up(verts: np.ndarray, faces: np.ndarray) -> str | None:
    """The file's up axis from the normal of its longest flat boundary loop (the hem), or ``None`` when
    the loops do not decide. ``verts (V, 3)`` as stored in the file.

    A loop is flat when its thickness across its best plane is under :data:`FLAT_LOOP` of its narrower
    width (singular values of its points): a hem or a leg opening is; the top opening of a sleeveless
    jumpsuit, neckline and arm holes in one loop, is not, and its best plane says nothing about up."""
    try:
        loops = boundary_loops(faces)
    except ValueError:
        return None
    best, best_length = None, 0.0
    for loop in loops:
        pts = verts[loop] - verts[loop].mean(0)
        _, spread, axes = np.linalg.svd(pts, full_matrices=False)
        length = float(np.linalg.norm(pts - np.roll(pts, 1, axis=0), axis=1).sum())
        if spread[2] <= FLAT_LOOP * spread[1] and length > best_length:
            best, best_length = axes[-1], length
    if best is None:
        return None
    y, z = abs(best[1]), abs(best[2])
    if max(y, z) < np.cos(np.radians(45.0)):
        return None
    return "y" if y > z else "z"


#: Thickness of a boundary loop across its best plane, as a share of its narrower width, below which the loop
#: is flat enough for its normal to give the up axis (hems and leg openings: at most 0.20 on the 12 templates as made
#: and 24 draped at rest on other bodies; necklines and top openings 0.27-0.98, a sleeveless top 0.58).
FLAT_LOOP = 0.25


def attachment_type(verts: np.ndarray, faces: np.ndarray) -> str:
    """``"ring"`` (waistband or strapless top), ``"shoulders"`` or ``"straps"`` from the top of
    Z-up ``verts (V, 3)`` (see the module docstring)."""
    top = verts[:, 2] > verts[:, 2].max() - 0.03
    upper = verts[verts[:, 2] > verts[:, 2].max() - 0.15, :2].mean(0)
    angle = np.arctan2(verts[top, 1] - upper[1], verts[top, 0] - upper[0])
    sectors = np.unique(np.floor((angle + np.pi) / (np.pi / 4)).astype(int) % 8)
    if len(sectors) == 8:  # the top goes all around: a waistband or a flared top edge
        return "ring"
    sel = faces[top[faces].all(1)]
    if len(sel) == 0:
        sel = faces[top[faces].any(1)]
    tri = verts[sel]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    if np.abs(cross[:, 2]).sum() <= 0.5 * np.linalg.norm(cross, axis=1).sum():
        return "ring"  # near-vertical cloth at the top: a strapless top edge, higher at the front
    slab = faces[(verts[faces, 2] > verts[:, 2].max() - 0.10).all(1)]
    labels = face_components(slab)
    sizes = np.bincount(labels, weights=face_areas(verts, slab))
    return "straps" if np.count_nonzero(sizes > 0.2 * sizes.max()) >= 2 else "shoulders"


def top_windows(kind: str, lm: BodyLandmarks) -> tuple[float, float]:
    """``(low, high)`` heights (m) where the top of a garment with attachment ``kind`` may lie."""
    return window_heights(kind, lm.waist_z, lm.armpit_z, float(lm.joints["neck"][0][2]))


def window_heights(kind: str, waist_z, armpit_z, neck_z):
    """:func:`top_windows` from the landmarks' heights (m; floats or arrays of one per body)."""
    if kind == "ring":
        return waist_z - 0.18, armpit_z + 0.15
    return armpit_z + 0.03, neck_z + 0.12


def fit_score(dist: np.ndarray, z: np.ndarray, band: float) -> tuple[float, float, float]:
    """How badly points at heights ``z (N,)`` with signed body distances ``dist (N,)`` sit on the
    body. Returns ``(score, top_gap, inside)``, all but ``inside`` in metres.

    ``score`` is the mean absolute deviation of the gap from its median over the top ``band``
    metres (a garment made for a body keeps an even gap to it there; moved up or down, one part
    comes closer and another moves away), plus 2 m times the fraction of points more than 3 mm
    inside the body, plus 5 times their mean depth. ``top_gap`` is the mean ``|dist|`` of the top
    4 cm; ``inside`` the fraction of points more than 1 cm inside.
    """
    upper = dist[z > z.max() - band]
    top = z > z.max() - 0.04
    depth = np.maximum(-dist - 0.003, 0.0)
    score = np.abs(upper - np.median(upper)).mean() + 2.0 * (depth > 0).mean() + 5.0 * depth.mean()
    return float(score), float(np.abs(dist[top]).mean()), float((dist < -0.01).mean())


def _search(sample: np.ndarray, lm: BodyLandmarks, window: tuple[float, float], start: np.ndarray, band: float,
            coarse_points: int = 400):
    """Best offset of ``sample (N, 3)`` (already moved by ``start (3,)``) with its top in ``window``.
    Returns ``(score, offset (3,), top_gap, inside)``."""
    top = sample[:, 2].max()
    zs = np.arange(window[0] - top, window[1] - top + 1e-9, 0.01)
    if len(zs) == 0:
        zs = np.array([0.5 * (window[0] + window[1]) - top])

    def score(dy, dz, points=sample):
        moved = points + [0.0, dy, dz]
        return fit_score(lm.sdf.query(moved), moved[:, 2], band)

    coarse = sample[:: max(1, len(sample) // coarse_points)]
    grid = [(score(dy, dz, coarse)[0], dy, dz) for dz in zs for dy in (-0.02, 0.0, 0.02)]
    _, by, bz = min(grid)
    best = (np.inf, by, bz)
    for step in (0.01, 0.005, 0.002):  # refine: 5 mm then 2 mm steps around the best
        _, by, bz = best
        fine = [(score(by + dy, bz + dz)[0], by + dy, bz + dz)
                for dz in step * np.arange(-2, 3) for dy in step * np.arange(-2, 3)
                if window[0] - 1e-9 <= top + bz + dz <= window[1] + 1e-9]
        best = min([best] + fine)
    s, by, bz = best
    _, gap, inside = score(by, bz)
    return s, start + [0.0, by, bz], gap, inside


def place(verts: np.ndarray, faces: np.ndarray, lm: BodyLandmarks, path, up: str | None = None,
          samples: int = SAMPLES, top_hint: float | None = None) -> Placement:
    """Place a garment (``verts (V, 3)`` metres, as stored in the file) on the body.

    Args:
        verts: file vertices scaled to metres, in the file's axes.
        faces: ``(F, 3)`` int64 triangles.
        lm: landmarks of the body's rest pose.
        path: the file, named in errors.
        up: ``"y"`` or ``"z"`` to force the file's up axis; detected when ``None``.
        samples: points scored per placement (fewer: faster and coarser, as in the body-shape search of
            :mod:`loosefit.garment.body_fit`).
        top_hint: where the top is expected, m: only heights within :data:`HINT_RANGE` of it are searched
            (the body-shape search knows it from the last shape's placement).

    Returns:
        The best :class:`Placement` (its offset applies to ``to_z_up(verts, placement.up)``).

    Raises:
        InputError: no plausible placement (see the module docstring), naming what was tried.
    """
    axes = (up,) if up else ((detect_up(verts, faces),) if detect_up(verts, faces) else ("z", "y"))
    pick = np.linspace(0, len(verts) - 1, min(len(verts), samples)).astype(int)
    body_x = float(0.5 * (lm.joints["hip"][0][0] + lm.joints["hip"][1][0]))
    found, tried = [], []
    attempts, fallback = [], False
    for axis in axes:
        kind = attachment_type(to_z_up(verts, axis), faces)
        attempts.append((axis, kind))
    for axis, kind in attempts:
        v = to_z_up(verts, axis)
        window = top_windows(kind, lm)
        if top_hint is not None:
            window = (max(window[0], top_hint - HINT_RANGE), min(window[1], top_hint + HINT_RANGE))
            if window[0] > window[1]:
                tried.append(f"{axis}-up as {kind}: {top_hint:.2f} m is outside its window")
                continue
        lo, hi = v.min(0), v.max(0)
        top_band = v[v[:, 2] > hi[2] - 0.04]
        start = np.array([
            body_x - 0.5 * (top_band[:, 0].min() + top_band[:, 0].max()),
            lm.center_y - 0.5 * (lo[1] + hi[1]),
            -lo[2],
        ])
        band = RING_BAND if kind == "ring" else HANGING_BAND
        score, offset, gap, inside = _search(v[pick] + start, lm, window, start, band, min(400, samples))
        top_z = float(hi[2] + offset[2])
        here_top = float(hi[2])
        if window[0] <= here_top <= window[1]:  # the file's own position, if plausible
            s_here, g_here, i_here = fit_score(lm.sdf.query(v[pick]), v[pick, 2], band)
            if s_here <= score + 0.003 and i_here <= MAX_INSIDE and g_here <= MAX_TOP_GAP:
                score, offset, gap, inside, top_z = s_here, np.zeros(3), g_here, i_here, here_top
        if kind == "ring":
            kind = "waistband" if abs(top_z - lm.waist_z) < abs(top_z - lm.armpit_z) else "strapless"
        tried.append(f"{axis}-up as {kind}: top between {window[0]:.2f} and {window[1]:.2f} m, best at "
                     f"{top_z:.2f} m with {100 * inside:.0f}% of points over 1 cm inside the body and a "
                     f"{100 * gap:.1f} cm gap at the top")
        if inside <= MAX_INSIDE and gap <= MAX_TOP_GAP:
            found.append(Placement(axis, kind, offset, top_z, score, gap, inside))
        elif len(tried) == len(attempts) and not found and not fallback:
            fallback = True  # the first reading of the top found nothing: try the other one
            attempts += [(a, "shoulders" if k == "ring" else "ring") for a, k in attempts]
    if not found:
        raise InputError(
            "no plausible placement on the body (at most "
            f"{100 * MAX_INSIDE:.0f}% inside, at most {100 * MAX_TOP_GAP:.0f} cm gap at the top); tried "
            + "; ".join(tried) + ". Check the unit (--unit) and up axis (--up), or move the garment onto the body",
            path,
        )
    return min(found, key=lambda p: p.score)
