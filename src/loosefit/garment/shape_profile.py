"""The first, cheap look of the body-shape search (:mod:`loosefit.garment.body_fit`): garment and bodies as
cylindrical profiles.

A body is reduced to the radius of its torso and legs (arms left out) about a vertical axis (the hips' midline,
the waist's front-back middle), in bins of :data:`LEVEL` of height and :data:`SECTORS` sectors around: the
largest radius of its vertices in each bin. A garment is reduced the same way, about its own axis (its top
band's left-right middle, its box's front-back middle: the placement's start), to the smallest and the largest
radius of points sampled on its surface (about one a square centimetre). The gap in a bin is the garment's
largest radius less the body's, the same statistic on both (a surface's radius varies across a sector), except
where a sleeve hangs beside the torso: a largest radius over :data:`FAR_WALL` out, and a smallest not as far
in, is a sleeve, and the smallest (the cloth over the torso) counts. This is the cylindrical version of the
signed distances that :func:`~loosefit.garment.placement.fit_score` reads, scored the same way (how uneven
over the top band, penalties for cloth inside, the top's gap, the floor) for every shape of a batch at once and
every height of the garment's top in the shape's window (:data:`TOP_STEP` apart), with the garment moved
front to back by :data:`DYS`. Anny's batched model makes a body in 1-2 ms, so a few hundred shapes over all
six keys cost a few seconds, where the exact score (the placement on the body's signed distance) costs about
0.25 s a shape. The best few are then scored exactly and refined (:func:`loosefit.garment.body_fit.find_shape`).

What the profiles do not see: the arms (a sleeve's fit; the exact score does), and cloth within a bin's error
of the body (:data:`INSIDE_TOLERANCE`). On a template on its own body, the gaps are even to about 5 mm but
for the shoulders' slope, where a radius is not a distance to the surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loosefit.garment.landmarks import JOINT_NAMES
from loosefit.garment.placement import RING_BAND, top_windows

#: Height of a bin, m.
LEVEL = 0.02
#: Sectors around the axis (15 degrees each).
SECTORS = 24
#: Front-back moves of the garment tried, m (as the placement's first search).
DYS = (-0.02, 0.0, 0.02)
#: Steps of the garment's top height within a shape's window, m.
TOP_STEP = 0.02
#: Points sampled on the garment's surface per square metre (one a square centimetre), at most
#: :data:`MAX_POINTS`.
DENSITY = 1e4
MAX_POINTS = 40000


@dataclass
class BodyProfiles:
    """Cylindrical profiles of the rest bodies of ``S`` shapes (see the module docstring).

    Attributes:
        radius: ``(S, Z, SECTORS)`` float32 largest radius of the torso and legs in each bin, m (NaN: empty);
            level ``i`` covers heights ``[i, i + 1) * LEVEL``.
        axis: ``(S, 2)`` the vertical axis (x, y), m: the hips' midline, the torso's front-back middle.
        waist_z, armpit_z, neck_z: ``(S,)`` the landmarks the garment's top windows hang from, m
            (as :func:`~loosefit.garment.landmarks.measure_body` measures them, the waist on the profiles).
    """

    radius: np.ndarray
    axis: np.ndarray
    waist_z: np.ndarray
    armpit_z: np.ndarray
    neck_z: np.ndarray


def body_profiles(verts: np.ndarray, joints: np.ndarray, joint_names: list[str], arm_weight: np.ndarray,
                  height: float = 2.6) -> BodyProfiles:
    """Profiles of rest bodies ``verts (S, V, 3)`` with joints ``(S, J, 3)`` (Anny's ``cmu_mb`` names,
    :meth:`~loosefit.body.anny_body.AnnyBody.rest_batch`); ``arm_weight (V, 2)``: skinning weight of the arm
    chains (the same for every shape of one topology). ``height``: the profiles' top, m."""
    verts = np.asarray(verts, np.float32)
    S = len(verts)
    idx = {k: [joint_names.index(n) for n in pair[0]] for k, pair in JOINT_NAMES.items()}
    hip = joints[:, idx["hip"]].mean(1)
    shoulder_z = joints[:, idx["shoulder"], 2].mean(1)
    torso = arm_weight.sum(1) < 0.3
    tv = verts[:, torso]
    z = tv[:, :, 2]
    # Binned about the hips' midline first (for the waist), then about the waist's front-back middle: the
    # placement's axis (lm.center_y).
    Z = int(np.ceil(height / LEVEL))
    level = np.floor(z / LEVEL).astype(np.int64)
    first = np.stack([hip[:, 0], hip[:, 1]], 1)
    radius = _radius_bins(tv, first, level, Z, largest=True)
    seam = (arm_weight.max(1) > 0.35) & (arm_weight.max(1) < 0.65)
    armpit_z = verts[:, seam, 2].min(1)
    neck_z = joints[:, idx["neck"][0], 2]
    # The waist: the narrowest torso section between a quarter and 70 % of the way from hips to shoulders.
    perimeter = _perimeter(radius)
    levels = (np.arange(Z) + 0.5) * LEVEL
    low = hip[:, 2] + 0.25 * (shoulder_z - hip[:, 2])
    high = hip[:, 2] + 0.7 * (shoulder_z - hip[:, 2])
    allowed = (levels[None] >= low[:, None]) & (levels[None] <= high[:, None]) & np.isfinite(perimeter)
    waist_z = levels[np.argmin(np.where(allowed, perimeter, np.inf), 1)]
    ring = np.abs(z - waist_z[:, None]) < 0.01
    y_mid = 0.5 * (np.where(ring, tv[:, :, 1], np.inf).min(1) + np.where(ring, tv[:, :, 1], -np.inf).max(1))
    axis = np.stack([hip[:, 0], y_mid], 1)
    radius = _radius_bins(tv, axis, level, Z, largest=True)
    return BodyProfiles(radius, axis.astype(np.float64), waist_z, armpit_z.astype(np.float64),
                        neck_z.astype(np.float64))


def _radius_bins(points: np.ndarray, axis: np.ndarray, level: np.ndarray, Z: int, largest: bool) -> np.ndarray:
    """``(S, Z, SECTORS)`` largest (or smallest) radius of ``points (S, N, 3)`` about ``axis (S, 2)`` in each
    bin, the points' levels given as ``level (S, N)`` int (outside ``[0, Z)``: left out); NaN where empty."""
    S = len(points)
    d = points[..., :2] - axis[:, None, :]
    radius = np.hypot(d[..., 0], d[..., 1]).astype(np.float32)
    sector = np.floor((np.arctan2(d[..., 1], d[..., 0]) + np.pi) / (2 * np.pi) * SECTORS).astype(np.int64) % SECTORS
    ok = (level >= 0) & (level < Z)
    flat = (np.arange(S)[:, None] * Z + level) * SECTORS + sector
    out = np.full(S * Z * SECTORS, -np.inf if largest else np.inf, np.float32)
    (np.maximum if largest else np.minimum).at(out, flat[ok], radius[ok])
    out[~np.isfinite(out)] = np.nan
    return out.reshape(S, Z, SECTORS)


def _perimeter(radius: np.ndarray) -> np.ndarray:
    """``(..., Z)`` perimeter of the polygon through each level's non-empty sectors' radii (``radius (..., Z,
    SECTORS)``, NaN where empty: a thin slab of a body leaves a few sectors without a vertex); NaN where fewer
    than half the sectors hold one."""
    angle = (np.arange(SECTORS) + 0.5) * 2 * np.pi / SECTORS
    x, y = radius * np.cos(angle), radius * np.sin(angle)
    valid = np.isfinite(radius)
    # An empty sector takes the last non-empty one's point (around the circle): a zero-length side.
    index = np.where(np.concatenate([valid, valid], -1), np.arange(2 * SECTORS), -1)
    last = np.maximum.accumulate(index, -1)[..., SECTORS:] % SECTORS
    x, y = np.take_along_axis(x, last, -1), np.take_along_axis(y, last, -1)
    perimeter = np.hypot(x - np.roll(x, 1, -1), y - np.roll(y, 1, -1)).sum(-1)
    return np.where(valid.sum(-1) >= SECTORS // 2, perimeter, np.nan)


@dataclass
class GarmentProfile:
    """A garment's cylindrical profile (see the module docstring), its top at height 0.

    Attributes:
        radius: ``(len(DYS), 2, K, SECTORS)`` smallest and largest radius of the garment's surface points in
            each bin about the axis moved by each of :data:`DYS`, m (NaN: none); level ``k`` covers depths
            ``[k, k + 1) * LEVEL`` below the top.
        depths: ``(N,)`` sorted depths of the surface points below the top, m (for the floor term).
        kind: ``"ring"`` or a hanging attachment (:func:`~loosefit.garment.placement.attachment_type`).
        x_offset, y_offset: move of the garment's own coordinates that puts its axis on the body's, less
            the body's axis, m (the placement's start: its top band centred left-right, its box front-back).
        top: height of its top in its own coordinates, m.
    """

    radius: np.ndarray
    depths: np.ndarray
    kind: str
    x_offset: float
    y_offset: float
    top: float


def garment_profile(verts: np.ndarray, faces: np.ndarray, kind: str, seed: int = 0) -> GarmentProfile:
    """The profile of a Z-up garment ``verts (V, 3)`` (m), ``faces (F, 3)``, read as attachment ``kind``."""
    verts = np.asarray(verts, np.float64)
    tri = verts[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    count = int(min(MAX_POINTS, max(len(verts), DENSITY * area.sum())))
    rng = np.random.default_rng(seed)  # the same points on every call: the profile is a function of the mesh
    which = rng.choice(len(faces), count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    pts = tri[which, 0] + u[:, None] * (tri[which, 1] - tri[which, 0]) + v[:, None] * (tri[which, 2] - tri[which, 0])
    pts = np.concatenate([pts, verts])
    top = float(verts[:, 2].max())
    band = verts[verts[:, 2] > top - 0.04]
    x_mid = 0.5 * (band[:, 0].min() + band[:, 0].max())
    y_mid = 0.5 * (verts[:, 1].min() + verts[:, 1].max())
    depth = top - pts[:, 2]
    K = int(np.ceil(depth.max() / LEVEL)) + 1
    level = np.floor(depth / LEVEL).astype(np.int64)[None]
    # The garment moved front-back by dy: its axis, in its own coordinates, by -dy.
    radius = np.stack([np.concatenate([_radius_bins(pts[None], np.array([[x_mid, y_mid - dy]]), level, K, largest)
                                       for largest in (False, True)]) for dy in DYS])
    return GarmentProfile(radius, np.sort(depth), kind, x_mid, y_mid, top)


#: A garment's largest radius in a bin this far out of the body is a sleeve's (or a flare's), m.
FAR_WALL = 0.06
#: Depth inside the body from which a bin counts as inside, m: the exact score's 3 mm plus the profiles' own
#: error (a bin's largest radius on a sloped surface; with 5 mm, a long shirt on its own tall body scored 14.8 mm
#: for bins "inside" at its shoulders, worse than on a shorter body of another gender, 11.6 mm).
INSIDE_TOLERANCE = 0.015
#: Gaps are clipped to this range in the evenness (m): a sleeve's or a flared hem's wide gap is not a misfit.
GAP_CLIP = (-0.05, 0.08)


def profile_scores(bodies: BodyProfiles, garment: GarmentProfile, band: float, gap_weight: float,
                   floor_weight: float, chunk: int = 16) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Score the garment on every body of ``bodies`` at its best top height and front-back move (see the
    module docstring): ``(score (S,), top (S,), dy (S,))``, m; ``score`` is ``inf`` where no height in the
    shape's window has the garment's top band on the body or the top's gap is over
    :data:`~loosefit.garment.placement.MAX_TOP_GAP`.

    The score mirrors the exact one of :func:`loosefit.garment.body_fit.find_shape`: the mean absolute
    deviation of the gap (clipped to :data:`GAP_CLIP`) from its mean over the top ``band``, plus 2 m times
    the share of bins more than 3 mm inside the body and 5 times their mean depth (over the whole garment),
    plus ``gap_weight`` times the mean gap of the top 4 cm, plus ``floor_weight`` times the mean depth of the
    garment's points below the floor."""
    from loosefit.garment.placement import MAX_TOP_GAP, window_heights

    S, Z, _ = bodies.radius.shape
    D, _, K, _ = garment.radius.shape
    lo, hi = window_heights(garment.kind, bodies.waist_z, bodies.armpit_z, bodies.neck_z)
    m_lo = np.ceil(lo / LEVEL - 1e-9).astype(int)
    m_hi = np.floor(hi / LEVEL + 1e-9).astype(int)
    step = max(1, int(round(TOP_STEP / LEVEL)))
    in_band = (np.arange(K) < max(1, int(round(band / LEVEL))))[None, None, :, None]
    at_top = (np.arange(K) < int(round(RING_BAND / LEVEL)))[None, None, :, None]
    best = np.full(S, np.inf)
    best_top = np.full(S, np.nan)
    best_dy = np.zeros(S)
    for start in range(0, S, chunk):
        rows = np.arange(start, min(S, start + chunk))
        tops = np.arange(m_lo[rows].min(), m_hi[rows].max() + 1, step)
        if len(tops) == 0:
            continue
        level = tops[:, None] - 1 - np.arange(K)[None]  # (T, K) body level of each garment level
        inside_z = (level >= 0) & (level < Z)
        rb = bodies.radius[rows][:, np.clip(level, 0, Z - 1)]  # (C, T, K, SECTORS)
        rb = np.where(inside_z[None, :, :, None], rb, np.nan)
        # The garment's axis is put on the body's (the placement's start), then moved by dy. The gap is the
        # garment's largest radius in a bin less the body's (the same statistic on both: a surface's radius
        # varies across a sector), unless that is over FAR_WALL out and the smallest radius is not FAR_WALL in:
        # then a sleeve beside the torso holds the largest, and the smallest (the wall over the torso) counts.
        # (A trouser leg's smallest radius is its far side, deep inside the leg: the largest counts.)
        walls = garment.radius[None, :, :, None] - rb[:, None, None]  # (C, D, 2, T, K, SECTORS)
        sleeve = (walls[:, :, 1] > FAR_WALL) & (walls[:, :, 0] > -FAR_WALL)
        gaps = np.where(sleeve, walls[:, :, 0], walls[:, :, 1])  # (C, D, T, K, SECTORS)
        valid = np.isfinite(gaps)
        g = np.where(valid, gaps, 0.0)
        upper = valid & in_band
        n_up = upper.sum((3, 4))
        clipped = np.clip(g, *GAP_CLIP)
        mean = (clipped * upper).sum((3, 4)) / np.maximum(n_up, 1)
        evenness = (np.abs(clipped - mean[..., None, None]) * upper).sum((3, 4)) / np.maximum(n_up, 1)
        depth = np.where(valid, np.maximum(-g - INSIDE_TOLERANCE, 0.0), 0.0)
        n = np.maximum(valid.sum((3, 4)), 1)
        inside = 2.0 * (depth > 0).sum((3, 4)) / n + 5.0 * depth.sum((3, 4)) / n
        top_bins = valid & at_top
        top_gap = (np.abs(g) * top_bins).sum((3, 4)) / np.maximum(top_bins.sum((3, 4)), 1)
        t = tops * LEVEL
        below = np.maximum(garment.depths[None] - t[:, None], 0.0).mean(1)  # (T,) depth below the floor
        score = evenness + inside + gap_weight * top_gap + floor_weight * below[None, None]
        allowed = (tops[None] >= m_lo[rows, None]) & (tops[None] <= m_hi[rows, None])  # (C, T)
        score = np.where(allowed[:, None] & (n_up > 0) & (top_bins.sum((3, 4)) > 0) & (top_gap <= MAX_TOP_GAP),
                         score, np.inf)
        flat = score.reshape(len(rows), -1)
        pick = np.argmin(flat, 1)
        best[rows] = flat[np.arange(len(rows)), pick]
        best_dy[rows] = np.asarray(DYS)[pick // len(tops)]
        best_top[rows] = t[pick % len(tops)]
    return best, best_top, best_dy
