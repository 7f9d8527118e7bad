"""Fitting a garment made for another body, as a garment tool does it.

A garment cut for a slimmer body sits inside this one (the direct placement of
:mod:`loosefit.garment.placement` refuses it); one cut for a larger body hangs away from it. Three steps
bring it onto the body without changing its cut:

1. **The body it was made for** (:func:`find_shape`): the Anny shape, over all six keys (:data:`SEARCH_KEYS`;
   age at least :data:`ADULT_AGE` unless no adult body can wear the garment), that minimises
   interpenetration plus gap at the garment's attachment. The exact score of a shape is the existing
   placement's (:func:`~loosefit.garment.placement.place` on :data:`SEARCH_SAMPLES` points):
   :func:`~loosefit.garment.placement.fit_score` over the garment's top :data:`SEARCH_BAND` (how uneven the gap
   is there, read on up to :data:`BAND_SAMPLES` of its vertices, plus the penalties for cloth more than 3 mm
   inside the body), plus :data:`GAP_WEIGHT` times the mean gap at the top 4 cm, plus :data:`FLOOR_WEIGHT`
   times the garment's mean depth below the floor, plus :data:`PRIOR` metres per unit of shape distance from
   the target. The evenness is what tells the body apart: a strapless top cut for a thin Anny (height 0.45,
   weight 0.12, gender 0.4) scores 0.5 mm on it and 1.8-3.4 mm on bodies 0.05-0.35 away in a key (over its
   top 10 cm). The band reaches past a strap dress's or a shirt's shoulders to the bust, a skirt's waistband
   to the hips; 45 cm would reach a dress's flared skirt (with the four-key search that preceded this one, a
   dress cut at weight 0.3 was found at 1.0). The mean
   gap alone would prefer the largest body the garment does not cut into (2 mm of gap where the garment was
   made with 14 mm of ease), hence its small weight. The prior breaks ties towards the target (the height of a
   body under a skirt's waistband is not seen), so that the drape is short.
   The exact score costs about 0.25 s a shape, too much for six keys, so the search looks first at the
   garment's and the bodies' cylindrical profiles (:mod:`loosefit.garment.shape_profile`: the same score on
   radii in 2 cm by 15 degree bins, 1-2 ms a shape, bodies made in batches): every shape of a grid of gender,
   weight and height (:data:`COARSE`, 125 shapes; at the target's other values), then a coordinate search on
   every key with steps :data:`PROFILE_STEPS` from the best :data:`STARTS` shapes at least :data:`DISTINCT`
   apart (at most :data:`MAX_PROFILES` shapes). Those are scored exactly, with the target at each height of
   the grid (the profiles leave out the arms, which show where a sleeved garment's body is: a long shirt cut
   for a tall body was put on a short one whose arms its sleeves went through), then a coordinate search on
   the exact score with steps :data:`STEPS`, each shape's height window narrowed to 5 cm around where the best
   shape's attachment landmark (waist, armpits or neck) puts the top; at most :data:`MAX_EVALUATIONS` shapes
   scored exactly. About 10 s in all on one core, for a garment of any size (the samples are fixed).
   Several shapes often fit about as well: bodies differ in more ways than a garment's cut shows, and a garment
   with 1 cm of ease fits a body 6 cm larger in girth nearly as evenly as its own. The shape found is a body the
   garment fits, within a few centimetres of girth of the one it was made on on the garments of
   ``benchmarks/garment_fit.py`` and of ``tests/garment/test_body_fit.py`` (which report and check both); when
   the drape from it still fails, the refusal names it as a ``--shape`` to import and simulate the garment on
   (:func:`shape_option`).
2. **Placed rigidly** on that body (the placement's axis swap and offset; the unit's scale).
3. **Draped** (:func:`drape`): Blender cloth on the body's collider while the body's vertices move linearly
   from the found shape to the target over :data:`MORPH_SECONDS`, then hold for :data:`SETTLE_SECONDS`
   (:data:`FIT_COLLISION_QUALITY` collision iterations a step: a body growing into a tight panel).
   The cloth's rest shape is the garment as placed (its cut is kept); its pinned vertices (the top 3 cm)
   follow the body change at their nearest body points (:func:`carry`).

The result is reported with the shape found and the final penetration: the share of vertices more than
2 mm inside the target body (:data:`INSIDE_DEPTH`).
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from loosefit.errors import InputError
from loosefit.garment.landmarks import measure_body
from loosefit.garment.placement import Placement, fit_score, place, to_z_up

#: Anny shape keys searched: all six.
SEARCH_KEYS = ("gender", "age", "muscle", "weight", "height", "proportions")
#: The grid of the profiles' first look: every combination of these values (other keys: the target's, age at
#: least :data:`ADULT_AGE`). The three keys that change a garment's fit most (``docs/guide.md``'s table).
COARSE = {"gender": (0.0, 0.25, 0.5, 0.75, 1.0), "weight": (0.0, 0.25, 0.5, 0.75, 1.0),
          "height": (0.0, 0.25, 0.5, 0.75, 1.0)}
#: Steps of the coordinate search on the profiles, over every key, in shape units.
PROFILE_STEPS = (0.12, 0.06)
#: Most shapes the profiles score (the grid included); the search is batched, 1-2 ms a shape.
MAX_PROFILES = 400
#: Shapes the profiles found best (at least :data:`DISTINCT` apart) whose exact score starts the last search.
STARTS = 3
DISTINCT = 0.2
#: Steps of the last coordinate search, on the exact score, in shape units.
STEPS = (0.12, 0.06, 0.03)
#: Objective per unit of Euclidean shape distance from the target, m: breaks ties towards the target.
PRIOR = 0.001
#: Depth of the garment's upper band whose gap evenness scores a shape, m.
SEARCH_BAND = 0.25
#: Weight of the mean gap at the top 4 cm in the objective.
GAP_WEIGHT = 0.05
#: Weight of the garment's mean depth below the floor (the soles, z = 0) in the objective: a garment is not made
#: to pass through the floor on its own body. Without it a sleeveless jumpsuit cut for a tall body (height 0.8)
#: was found on the shortest (0.0), its legs 10 cm through the floor; the top's evenness does not see height.
FLOOR_WEIGHT = 1.0
#: Points the placement scores per shape during the search (the final placement uses all its samples).
SEARCH_SAMPLES = 300
#: Vertices of the garment's top band the exact score reads, at most.
BAND_SAMPLES = 400
#: Most shapes scored exactly in one search.
MAX_EVALUATIONS = 36
#: The youngest age searched unless no adult body can wear the garment (Anny's age 0.5 is the average adult; below
#: it the body is a child's). A younger body is looked for only when the best adult profile scores over 2 m times
#: :data:`CHILD_INSIDE`: what the profiles' penalty alone gives when that share of the bins is inside the body
#: (:data:`~loosefit.garment.shape_profile.INSIDE_TOLERANCE`). A skirt and a long shirt made on children (age
#: 0.2, 0.25) did not get there: they were found on the shortest adult body, within 5 cm of their girths.
ADULT_AGE = 0.5
CHILD_INSIDE = 0.03
#: The ages the profiles try, then, below :data:`ADULT_AGE`.
CHILD_AGES = (0.1, 0.25, 0.4)
#: Blender cloth's collision iterations a solver step in a fit's drape (the simulation's default is 2). A body
#: growing into a garment cut for a smaller one presses a tight panel outwards: with 2, a dress made on a short
#: body (height 0.1) let the default body's breasts through its bodice, 17 vertices 10-22 mm inside it, and the
#: import was refused; with 4 it landed with none inside (as with 10 solver steps a frame instead of 5, at more
#: cost; ``benchmarks/garment_fit.py``).
FIT_COLLISION_QUALITY = 4
#: Seconds the body takes to change shape in the drape, and seconds it then holds.
MORPH_SECONDS = 1.0
SETTLE_SECONDS = 0.5
#: Frames per second of the drape.
FPS = 30.0
#: A vertex deeper than this inside the body counts as penetrating in the reports, m.
INSIDE_DEPTH = 0.002


@dataclass
class ShapeFit:
    """The body a garment was made for.

    Attributes:
        shape: the Anny shape found (an :class:`~loosefit.body.anny_body.AnnyShape`).
        placement: the garment's placement on that body.
        unit: the file unit used.
        objective: the shape's objective, m (see the module docstring).
        evaluations: shapes scored exactly.
        profiles: shapes scored on their profiles (:mod:`loosefit.garment.shape_profile`).
    """

    shape: object
    placement: Placement
    unit: str
    objective: float
    evaluations: int
    profiles: int = 0


def _anny(body, path):
    from loosefit.body.anny_body import AnnyBody

    if not isinstance(body, AnnyBody):
        raise InputError(f"fitting a garment made for another body needs the Anny body (its shape keys), not "
                         f"{body.name!r}", path)
    return body


@dataclass(frozen=True)
class Search:
    """How hard :func:`find_shape` looks: the profiles' grid (key -> values) and coordinate steps, the most
    shapes they score, the exact coordinate steps and the most shapes scored exactly, and the drape's length.
    The defaults are the module's constants; a smaller search is for quick checks."""

    coarse: tuple = tuple(COARSE.items())
    steps: tuple = STEPS
    max_evaluations: int = MAX_EVALUATIONS
    morph_seconds: float = MORPH_SECONDS
    settle_seconds: float = SETTLE_SECONDS
    profile_steps: tuple = PROFILE_STEPS
    max_profiles: int = MAX_PROFILES
    starts: int = STARTS


def find_shape(scaled: dict, faces: np.ndarray, body, path, up: str | None = None, search: Search = Search(),
               check=None) -> ShapeFit:
    """The Anny shape the garment was made for (step 1 of the module docstring).

    Args:
        scaled: unit -> ``(V, 3)`` file vertices scaled to metres (one entry per plausible unit).
        faces: ``(F, 3)`` int64.
        body: the target :class:`~loosefit.body.anny_body.AnnyBody`; its shape is the prior's centre.
        path: the file, named in errors.
        up: the file's up axis, or ``None`` to detect it.
        search: the grids, steps and numbers of shapes scored.
        check: called as ``check(placed (V, 3), landmarks)`` on the first shape with a placement; it raises to
            refuse the garment whatever the shape (a piece hanging free).

    Raises:
        InputError: no shape the search scored exactly gives a plausible placement.
    """
    from loosefit.body.anny_body import AnnyShape

    body = _anny(body, path)
    target = body.shape
    target_values = np.array([getattr(target, k) for k in SEARCH_KEYS])
    memo: dict = {}
    refusals: list[str] = []

    def evaluate(values: tuple) -> float:
        values = _round(values, bounds)
        if values in memo:
            return memo[values][0]
        shape = AnnyShape(**dict(zip(SEARCH_KEYS, values)))
        lm = measure_body(body, shape, like=profiles.target_sdf)
        best = (np.inf, None, None, shape, lm)
        distance = float(np.linalg.norm(np.subtract(values, target_values)))
        for unit, verts in scaled.items():
            hint = None
            if hints.get(unit) is not None:  # the top moves with its landmark from the best shape so far
                top_z, attachment, anchor = hints[unit]
                hint = top_z + _anchor(lm, attachment) - anchor
            try:
                p = place(verts, faces, lm, path, up, samples=SEARCH_SAMPLES, top_hint=hint)
            except InputError as err:
                refusals.append(f"{_short(values)}: {err.problem.split('; tried ')[-1][:200]}")
                continue
            if check is not None and not checked:
                checked.append(True)
                check(to_z_up(verts, p.up) + p.offset, lm)
            pts = to_z_up(verts[_scored(verts, p.up, pick, unit)], p.up) + p.offset
            score = (fit_score(lm.sdf.query(pts), pts[:, 2], SEARCH_BAND)[0] + GAP_WEIGHT * p.top_gap
                     + FLOOR_WEIGHT * np.maximum(-pts[:, 2], 0.0).mean() + PRIOR * distance)
            if score < best[0]:
                best = (score, p, unit, shape, lm)
        memo[values] = best
        if best[1] is not None and (best_seen[0] is None or best[0] < best_seen[0]):
            best_seen[0] = best[0]
            hints[best[2]] = (best[1].top_z, best[1].attachment, _anchor(lm, best[1].attachment))
        return best[0]

    pick: dict = {}
    hints: dict = {}
    best_seen = [None]
    checked: list = []
    # Step A: the profiles' grid and coordinate search (cheap: module loosefit.garment.shape_profile).
    bounds = np.array([[min(ADULT_AGE, target.age), 1.0] if k == "age" else [0.0, 1.0] for k in SEARCH_KEYS])
    profiles = _ProfileSearch(scaled, faces, body, up, target_values, search)
    starts = profiles.run(bounds)
    # Step B: the best of them scored exactly, with the target at every height of the grid (the profiles leave
    # out the arms, which show a sleeved garment's height: a long shirt cut for a tall body was put on a short
    # one, its sleeves through the arms), then the exact coordinate search.
    heights = dict(search.coarse).get("height", ())
    for values in starts + [_round(np.where(np.array(SEARCH_KEYS) == "height", h, target_values), bounds)
                            for h in heights] + [tuple(target_values)]:
        evaluate(values)
    best = min(memo, key=lambda k: memo[k][0])
    if not np.isfinite(memo[best][0]):
        raise InputError(
            f"no plausible placement on any Anny body tried ({len(memo)} shapes, the best of {profiles.count} "
            "looked at; " + "; ".join(refusals[:3]) + ")", path)
    for step in search.steps:
        improved = True
        while improved and len(memo) < search.max_evaluations:
            improved = False
            for i, sign in itertools.product(range(len(SEARCH_KEYS)), (-1.0, 1.0)):
                if len(memo) >= search.max_evaluations:
                    break
                candidate = list(best)
                candidate[i] = candidate[i] + sign * step
                candidate = _round(candidate, bounds)
                if candidate != best and evaluate(candidate) < memo[best][0] - 1e-6:
                    best, improved = candidate, True
    score, found, unit, shape, lm = memo[best]
    # The final placement on the found body with every sample point, near the search's.
    placement = place(scaled[unit], faces, lm, path, found.up, top_hint=found.top_z)
    return ShapeFit(shape=shape, placement=placement, unit=unit, objective=float(score), evaluations=len(memo),
                    profiles=profiles.count)


def _scored(verts: np.ndarray, up: str, pick: dict, unit: str) -> np.ndarray:
    """The vertices the exact score reads (kept in ``pick`` per unit and up axis): up to :data:`BAND_SAMPLES` of
    the garment's top :data:`SEARCH_BAND`, whose gap's evenness tells the bodies apart, and
    :data:`SEARCH_SAMPLES` spread over the whole garment for the penalties (300 spread over all of a long dress
    left 60 in its band: a score noisier than the differences between bodies)."""
    if (unit, up) not in pick:
        z = to_z_up(verts, up)[:, 2]
        band = np.nonzero(z > z.max() - SEARCH_BAND)[0]
        band = band[np.linspace(0, len(band) - 1, min(len(band), BAND_SAMPLES)).astype(int)]
        spread = np.linspace(0, len(verts) - 1, min(len(verts), SEARCH_SAMPLES)).astype(int)
        pick[unit, up] = np.union1d(band, spread)
    return pick[unit, up]


def _round(values, bounds: np.ndarray) -> tuple:
    """Shape values clipped to ``bounds (K, 2)`` and rounded to 3 decimals (the memo's key)."""
    return tuple(round(float(np.clip(v, lo, hi)), 3) for v, (lo, hi) in zip(values, bounds))


class _ProfileSearch:
    """Step A of :func:`find_shape`: the grid and the coordinate search on
    :func:`~loosefit.garment.shape_profile.profile_scores`, batched (one model call and one scoring per sweep)."""

    def __init__(self, scaled: dict, faces: np.ndarray, body, up, target_values: np.ndarray, search: Search):
        from loosefit.garment.placement import attachment_type, detect_up
        from loosefit.garment.shape_profile import garment_profile

        self.body, self.target, self.search = body, target_values, search
        target = measure_body(body)
        self.arm_weight, self.target_sdf = target.arm_weight, target.sdf
        self.garments = []
        for verts in scaled.values():
            axes = (up,) if up else ((detect_up(verts, faces),) if detect_up(verts, faces) else ("z", "y"))
            for axis in axes:
                v = to_z_up(verts, axis)
                self.garments.append(garment_profile(v, faces, attachment_type(v, faces)))
        self.scores: dict = {}

    @property
    def count(self) -> int:
        return len(self.scores)

    def score(self, shapes: list[tuple]) -> None:
        """Score the shapes not scored yet (values in :data:`SEARCH_KEYS` order)."""
        from loosefit.body.anny_body import AnnyShape
        from loosefit.garment.shape_profile import body_profiles, profile_scores

        new = [s for s in dict.fromkeys(shapes) if s not in self.scores]
        if not new:
            return
        verts, joints = self.body.rest_batch([AnnyShape(**dict(zip(SEARCH_KEYS, s))) for s in new])
        profiles = body_profiles(verts, joints, self.body.joint_names, self.arm_weight)
        score = np.min([profile_scores(profiles, g, SEARCH_BAND, GAP_WEIGHT, FLOOR_WEIGHT)[0]
                        for g in self.garments], 0)
        prior = PRIOR * np.linalg.norm(np.asarray(new) - self.target, axis=1)
        self.scores.update(zip(new, (score + prior).tolist()))

    def run(self, bounds: np.ndarray) -> list[tuple]:
        """The grid, the child's ages when no adult body can wear the garment, and the coordinate search from
        the best :attr:`Search.starts` distinct shapes. Returns those shapes, best first."""
        coarse = dict(self.search.coarse)
        age = SEARCH_KEYS.index("age")

        def grid(ages):
            points = []
            for combo in itertools.product(*coarse.values(), ages):
                values = self.target.copy()
                for k, v in zip(coarse, combo[:-1]):
                    values[SEARCH_KEYS.index(k)] = v
                values[age] = combo[-1]
                points.append(_round(values, bounds))
            return points

        self.score(grid([max(self.target[age], bounds[age][0])]))
        if min(self.scores.values()) > 2.0 * CHILD_INSIDE and bounds[age][0] > 0.0:  # no adult body wears it
            bounds[age][0] = 0.0  # for the exact search too (the caller's bounds)
            self.score(grid(CHILD_AGES))
        starts = self._distinct(self.search.starts)
        for n, start in enumerate(starts):
            best = start
            for step in self.search.profile_steps:
                while self.count < self.search.max_profiles:
                    around = [_round(np.add(best, sign * step * np.eye(len(best))[i]), bounds)
                              for i, sign in itertools.product(range(len(best)), (-1.0, 1.0))]
                    self.score(around)
                    better = min(around, key=self.scores.get)
                    if self.scores[better] >= self.scores[best] - 1e-6:
                        break
                    best = better
            starts[n] = best
        return [s for s in dict.fromkeys(sorted(starts, key=self.scores.get)) if np.isfinite(self.scores[s])]

    def _distinct(self, count: int) -> list[tuple]:
        """The best ``count`` shapes scored, each at least :data:`DISTINCT` from the others in some key."""
        out = []
        for s in sorted(self.scores, key=self.scores.get):
            if not np.isfinite(self.scores[s]) or len(out) == count:
                break
            if all(np.abs(np.subtract(s, o)).max() >= DISTINCT for o in out):
                out.append(s)
        return out


def shape_option(shape) -> str:
    """The command-line option that selects Anny ``shape``: ``--shape gender=1,weight=0.2`` (the values that
    are not 0.5, the default of an unnamed key; ``gender=0.5`` for the average body)."""
    values = ",".join(f"{k}={getattr(shape, k):g}" for k in SEARCH_KEYS if getattr(shape, k) != 0.5)
    return f"--shape {values or 'gender=0.5'}"


def _anchor(lm, attachment: str) -> float:
    """The body height a top of this attachment follows: the waist, the armpits or the neck joint."""
    if attachment == "waistband":
        return lm.waist_z
    return lm.armpit_z if attachment == "strapless" else float(lm.joints["neck"][0][2])


def _short(values) -> str:
    return ",".join(f"{k}={v:.2f}" for k, v in zip(SEARCH_KEYS, values))


def carry(points: np.ndarray, source: np.ndarray, target: np.ndarray, k: int = 8) -> np.ndarray:
    """How the body change from ``source (Vb, 3)`` to ``target (Vb, 3)`` (the same body's vertices in two
    shapes) moves ``points (N, 3)``: the inverse-distance weighted mean displacement of each point's ``k``
    nearest source vertices. Returns ``(N, 3)`` float64, m."""
    source = np.asarray(source, np.float64)
    dist, nearest = cKDTree(source).query(np.asarray(points, np.float64), k=k)
    w = 1.0 / np.maximum(dist, 1e-6)
    w /= w.sum(1, keepdims=True)
    change = np.asarray(target, np.float64) - source
    return np.einsum("nk,nkd->nd", w, change[nearest])


def fit_drape_params(params=None):
    """The simulation parameters of a fit's drape: ``params`` as given, or by default the simulation's defaults
    with :data:`FIT_COLLISION_QUALITY` collision iterations."""
    from loosefit.sim.params import SimParams

    return params if params is not None else SimParams(collision_quality=FIT_COLLISION_QUALITY)


def drape(verts: np.ndarray, faces: np.ndarray, pinned: np.ndarray, body, source, target=None, params=None,
          morph_seconds: float = MORPH_SECONDS, settle_seconds: float = SETTLE_SECONDS) -> tuple[np.ndarray, dict]:
    """Drape a garment from the body of shape ``source`` onto the shape ``target`` (step 3 of the module
    docstring) with Blender cloth.

    Args:
        verts: ``(V, 3)`` garment on the rest body of shape ``source``, m; also the cloth's rest shape.
        faces: ``(F, 3)`` int64.
        pinned: ``(V,)`` bool: vertices that follow the body change exactly.
        body: an Anny body; ``target`` ``None`` is its own shape.
        source, target: :class:`~loosefit.body.anny_body.AnnyShape`.
        params: :class:`~loosefit.sim.params.SimParams` (defaults when ``None``).

    Returns:
        ``(verts (V, 3) float64 on the target's rest body, stats)``: ``stats`` has the frames, the solver
        steps per frame, the wall time and ms per frame.
    """
    import time

    from loosefit.sim.collider import inflated_rest, steps_per_frame
    from loosefit.sim.params import SimParams
    from loosefit.sim.preroll import morph_frames
    from loosefit.sim.sequence import backend_run_cloth

    params = params or SimParams()
    run_cloth = backend_run_cloth("blender")
    target = target or body.shape
    proxy = body.collision_proxy()
    morph, settle = int(round(morph_seconds * FPS)), int(round(settle_seconds * FPS))
    collider, weight = morph_frames(inflated_rest(body, proxy, source), inflated_rest(body, proxy, target),
                                    morph, settle)
    verts = np.asarray(verts, np.float64)
    change = carry(verts, body.rest_verts(source), body.rest_verts(target))
    garment_frames = (verts[None] + weight[:, None, None] * change[None]).astype(np.float32)
    if params.adaptive_quality:
        steps = steps_per_frame(collider, garment_frames[0], params.collision_distance, params.quality)
        params = dataclasses.replace(params, quality=steps)
    floor = float(min(body.rest_verts(source)[:, 2].min(), body.rest_verts(target)[:, 2].min()))
    start = time.perf_counter()
    out, seconds = run_cloth(np.asarray(faces, np.int64), np.asarray(pinned, bool), garment_frames, collider,
                             proxy.faces, params, FPS, floor=floor)
    stats = {"frames": int(len(out)), "steps_per_frame": int(params.quality),
             "ms_per_frame": round(1e3 * float(seconds.mean()), 1), "wall_s": round(time.perf_counter() - start, 2)}
    return out[-1].astype(np.float64), stats


def inside_percent(verts: np.ndarray, sdf, depth: float = INSIDE_DEPTH) -> float:
    """Share of ``verts (V, 3)`` more than ``depth`` m inside the body, percent."""
    return float(100.0 * (sdf.query(np.asarray(verts, np.float64)) < -depth).mean())


def fit_to_body(scaled: dict, faces: np.ndarray, body, path, up: str | None = None, params=None,
                search: Search = Search(), pieces: np.ndarray | None = None, check=None):
    """Steps 1-3 of the module docstring for a repaired garment.

    Args:
        scaled: unit -> ``(V, 3)`` file vertices in metres, in the file's axes.
        faces: ``(F, 3)`` int64.
        body: the target Anny body.
        path: the file, named in errors.
        up: the file's up axis or ``None``.
        params: simulation parameters of the drape (:func:`fit_drape_params` when ``None``).
        search: how hard to look for the shape, and how long the drape is.
        pieces: ``(V,)`` piece label of each vertex (each piece is pinned at its own top); one piece when ``None``.
        check: called as ``check(placed (V, 3), landmarks of the found body)`` before the drape; it raises
            to refuse the placement.

    Returns:
        ``(verts (V, 3) on the target body, fit (ShapeFit), placed (V, 3) on the found body, info dict)``;
        ``info`` holds the shape found, the drape's statistics and the penetration before and after.
    """
    fit = find_shape(scaled, faces, body, path, up, search, check)
    placed = to_z_up(scaled[fit.unit], fit.placement.up) + fit.placement.offset
    from loosefit.garment.importer import top_pins

    pinned = top_pins(placed, np.zeros(len(placed), np.int64) if pieces is None else pieces)
    if check is not None:
        check(placed, measure_body(body, fit.shape))
    target_sdf = measure_body(body).sdf
    verts, stats = drape(placed, faces, pinned, body, fit.shape, params=fit_drape_params(params),
                         morph_seconds=search.morph_seconds, settle_seconds=search.settle_seconds)
    info = {
        "shape": {k: round(getattr(fit.shape, k), 3) for k in SEARCH_KEYS},
        "shape_option": shape_option(fit.shape),
        "objective": round(fit.objective, 5),
        "evaluations": fit.evaluations,
        "profiles": fit.profiles,
        "inside_before_percent": round(inside_percent(placed, target_sdf), 2),
        "inside_after_drape_percent": round(inside_percent(verts, target_sdf), 2),
        "drape": stats,
    }
    return verts, fit, placed, info


#: Share (percent) of a garment's vertices more than :data:`INSIDE_DEPTH` inside a body above which a garment
#: whose body is not recorded is refused on it rather than simulated (the simulation would start with the
#: cloth through the body).
REFIT_INSIDE_LIMIT = 1.0


def refit(garment, body, path=None, params=None, morph_seconds: float = MORPH_SECONDS,
          settle_seconds: float = SETTLE_SECONDS):
    """A :class:`~loosefit.garment.garment.Garment` made on one Anny body, brought onto ``body`` of another shape.

    The garment's recorded body shape (``garment.body_shape``) is where the drape starts (step 3 of the module
    docstring: the body morphs from that shape to ``body``'s while Blender cloth follows; pins carried). A
    garment made on this very shape, or on a body that is not Anny, is returned as it is. A garment with no
    recorded shape (a sidecar of an older version) is checked instead: more than :data:`REFIT_INSIDE_LIMIT`
    percent of it more than 2 mm inside ``body`` is refused, naming ``path``, since it was made for another body.

    Args:
        garment: the garment in the rest pose of its recorded body.
        body: the body to simulate it on.
        path: the garment's file, named in errors.
        params: simulation parameters of the drape (:func:`fit_drape_params` when ``None``).

    Returns:
        ``(garment on body's rest pose, info)``: ``info`` is ``None`` when nothing was done, else it has the
        shape draped from and to, the penetration into ``body`` before and after (percent of vertices more
        than 2 mm inside), and the drape's statistics; it is also stored as ``params["refit"]``.
    """
    from loosefit.body.anny_body import AnnyBody, AnnyShape
    from loosefit.garment.garment import shape_record

    target = shape_record(getattr(body, "shape", None))
    if not isinstance(body, AnnyBody) or garment.body_shape == target:
        return garment, None
    sdf = measure_body(body).sdf
    before = inside_percent(garment.verts, sdf)
    if garment.body_shape is None:
        if before > REFIT_INSIDE_LIMIT:
            raise InputError(f"{before:.1f}% of the garment's vertices are more than {1e3 * INSIDE_DEPTH:g} mm inside "
                             f"this body (over {REFIT_INSIDE_LIMIT:g}%) and its file does not say which body it was "
                             "made on: import the mesh again with `loosefit garment import FILE --fit` and this "
                             "body's --shape", path)
        return garment, None
    verts, stats = drape(garment.verts, garment.faces, garment.pinned, body, AnnyShape(**garment.body_shape),
                         params=fit_drape_params(params), morph_seconds=morph_seconds, settle_seconds=settle_seconds)
    info = {"from_shape": garment.body_shape, "to_shape": target, "inside_before_percent": round(before, 2),
            "inside_after_percent": round(inside_percent(verts, sdf), 2), "drape": stats}
    return dataclasses.replace(garment, verts=verts.astype(np.float32), body_shape=target,
                               params={**garment.params, "refit": info}), info
