"""Parametric garment templates fitted to a body in its rest pose.

Construction, for every kind:

1. **Upper body** (dress, long shirt, jumpsuit): the body surface above the waist is cut along
   level sets (neckline, sleeve ends or straps and arm holes, waist) and the patch is inflated to
   the ease distance with smoothing, which bridges the armpits and other folds.
2. **Hanging parts**: rings of vertices around a vertical axis, stitched ring to ring
   (:mod:`loosefit.garment.tubes`). Each ring's radius follows the convex hull of the body below
   the waist accumulated downwards (so cloth hangs from the hips instead of clinging to the legs),
   plus ease, plus a flare cone, plus ripples; the hem height varies around the body. Trouser
   legs branch from the pelvis ring along a crotch seam.
3. **Remeshing** of the whole piece to the target edge length (:mod:`loosefit.garment.remesh`),
   then a push out of the body to the clearance, measured with the body's signed distance at
   vertices and edge midpoints.

Every continuous parameter is drawn from the seed within its draw range, and can be given by
keyword within its allowed range; the values used are stored in ``Garment.params``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from loosefit.body.base import BodyModel
from loosefit.errors import InputError
from loosefit.garment.fitting import inflate, orient_outward, push_out
from loosefit.garment.garment import Garment, shape_record
from loosefit.garment.landmarks import BodyLandmarks, measure_body
from loosefit.garment.level_cut import cut_mesh
from loosefit.garment.mesh_checks import boundary_loops, face_components, mesh_report
from loosefit.garment.remesh import ReferenceSurface, clean_up, remesh
from loosefit.garment.tubes import MeshBuilder, build_tube, convex_radius, periodic_interp, polar

KINDS = ("skirt", "dress", "long_shirt", "jumpsuit")

#: Minimum distance (metres) from the body of every vertex and edge midpoint of a template.
CLEARANCE = 0.005
#: Allowed target edge lengths, metres (about 20k down to 1k vertices for a dress).
EDGE_LENGTH_RANGE = (0.006, 0.06)


@dataclass(frozen=True)
class Param:
    """A template parameter: drawn uniformly in ``draw`` from the seed, accepted in ``allowed``."""

    draw: tuple[float, float]
    allowed: tuple[float, float]
    doc: str


_SKIRT = {
    "waist_offset": Param((-0.06, 0.02), (-0.15, 0.08), "waistline height above the natural waist, m"),
    "length": Param((0.35, 0.8), (0.1, 1.3), "waist to front hem, m"),
    "flare": Param((2.0, 32.0), (0.0, 45.0), "half angle of the flare cone below the waist, degrees"),
    "hip_ease": Param((0.01, 0.05), (0.005, 0.12), "gap to the hips and legs, m"),
    "hem_slope": Param((-0.02, 0.1), (-0.2, 0.3), "back hem lower than the front by, m"),
    "hem_irregularity": Param((0.0, 0.05), (0.0, 0.15), "amplitude of hem height waves, m"),
    "ripple": Param((0.0, 0.03), (0.0, 0.08), "amplitude of radial folds at the hem, m"),
    "ripple_lobes": Param((5.0, 12.0), (2.0, 24.0), "number of radial folds (rounded)"),
}
_BODICE = {
    "bodice_ease": Param((0.012, 0.03), (0.006, 0.08), "gap between bodice and torso, m"),
    "neck_width": Param((0.075, 0.11), (0.07, 0.14), "half width of the neckline, m"),
    "neck_depth_front": Param((0.1, 0.22), (0.08, 0.3), "neckline depth at the front, m"),
    "neck_depth_back": Param((0.07, 0.13), (0.06, 0.25), "neckline depth at the back, m"),
}
_STRAPS = {
    "strap_width": Param((0.025, 0.06), (0.015, 0.08), "strap width, m"),
    "strap_offset": Param((0.085, 0.115), (0.075, 0.13), "distance of the strap centre from the midline, m"),
    "top_height_front": Param((0.0, 0.07), (-0.05, 0.12), "front top edge above the armpit, m"),
    "top_height_back": Param((-0.04, 0.03), (-0.1, 0.1), "back top edge above the armpit, m"),
}
_SLEEVES = {
    "sleeve_ease": Param((0.015, 0.04), (0.008, 0.08), "gap between sleeve and arm, m"),
}

PARAMS: dict[str, dict[str, Param]] = {
    "skirt": {**_SKIRT, "waist_ease": Param((0.008, 0.02), (0.005, 0.05), "gap at the waistband, m")},
    "dress": {
        **_SKIRT,
        "length": Param((0.45, 0.95), (0.1, 1.3), "waist to front hem, m"),
        **_BODICE,
        **_STRAPS,
        **_SLEEVES,
        "sleeve_length": Param((-0.35, 0.6), (0.0, 0.95), "sleeve end as a fraction of shoulder to wrist; below 0.12: straps"),
    },
    "long_shirt": {
        **_SKIRT,
        "length": Param((0.33, 0.5), (0.15, 0.7), "waist to front hem, m"),
        "flare": Param((0.0, 8.0), (0.0, 30.0), "half angle of the flare below the waist, degrees"),
        "hip_ease": Param((0.02, 0.05), (0.005, 0.12), "gap to the hips and thighs, m"),
        "hem_slope": Param((0.0, 0.06), (-0.2, 0.3), "back hem lower than the front by, m"),
        "hem_irregularity": Param((0.0, 0.02), (0.0, 0.15), "amplitude of hem height waves, m"),
        "ripple": Param((0.0, 0.01), (0.0, 0.08), "amplitude of radial folds at the hem, m"),
        **_BODICE,
        "bodice_ease": Param((0.02, 0.045), (0.006, 0.08), "gap between shirt and torso, m"),
        "neck_depth_front": Param((0.08, 0.14), (0.08, 0.3), "neckline depth at the front, m"),
        **_SLEEVES,
        "sleeve_length": Param((0.82, 0.95), (0.2, 0.95), "cuff as a fraction of shoulder to wrist"),
    },
    "jumpsuit": {
        "waist_offset": Param((-0.04, 0.02), (-0.15, 0.08), "waistline height above the natural waist, m"),
        **_BODICE,
        **_STRAPS,
        "hip_ease": Param((0.015, 0.04), (0.005, 0.12), "gap to the hips, m"),
        "crotch_drop": Param((0.04, 0.12), (0.03, 0.25), "crotch seam below the body's crotch, m"),
        "length": Param((0.45, 0.62), (0.15, 1.0), "crotch seam to leg hem, m"),
        "leg_flare": Param((0.0, 15.0), (0.0, 30.0), "half angle of the leg flare, degrees"),
        "leg_ease": Param((0.03, 0.07), (0.01, 0.15), "gap between trouser leg and leg, m"),
        "leg_gap": Param((0.008, 0.02), (0.004, 0.05), "gap between the two legs' inner sides, m"),
        "hem_irregularity": Param((0.0, 0.02), (0.0, 0.1), "amplitude of leg hem height waves, m"),
    },
}


def draw_params(kind: str, seed: int, **overrides) -> dict:
    """The parameters of a template: each drawn from ``seed`` unless given.

    Raises:
        InputError: unknown kind or parameter name, or a value outside its allowed range.
    """
    if kind not in PARAMS:
        raise InputError(f"unknown garment kind {kind!r}; kinds are {list(KINDS)}")
    specs = PARAMS[kind]
    unknown = sorted(set(overrides) - set(specs))
    if unknown:
        raise InputError(f"unknown {kind} parameter(s) {unknown}; known: {sorted(specs)}")
    rng = np.random.default_rng([int(seed), KINDS.index(kind)])
    params = {}
    for name, spec in specs.items():
        drawn = float(rng.uniform(*spec.draw))  # always drawn, so overrides do not shift the others
        if name in overrides:
            try:
                value = float(overrides[name])
            except (TypeError, ValueError):
                raise InputError(f"{kind} parameter {name}={overrides[name]!r} is not a number") from None
            lo, hi = spec.allowed
            if not lo <= value <= hi:
                raise InputError(f"{kind} parameter {name}={value} is outside [{lo}, {hi}] ({spec.doc})")
        else:
            value = drawn
        params[name] = value
    if "ripple_lobes" in params:
        params["ripple_lobes"] = float(round(params["ripple_lobes"]))
    if kind == "dress" and params["sleeve_length"] < 0.12:
        params["sleeve_length"] = 0.0  # straps
    # Shape of the hem waves and fold phases (not parameters a user would set by hand).
    params["hem_phases"] = rng.uniform(0, 2 * np.pi, 4).tolist()
    params["hem_weights"] = rng.uniform(0.3, 1.0, 4).tolist()
    params["ripple_phase"] = float(rng.uniform(0, 2 * np.pi))
    params["seed"] = int(seed)
    return params


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def _hem_waves(theta: np.ndarray, params: dict) -> np.ndarray:
    """Hem height variation in ``[-1, 1]`` around the body (harmonics 2 to 5)."""
    w = np.asarray(params["hem_weights"])
    k = np.arange(2, 6)
    waves = (w[None] * np.cos(k[None] * theta[:, None] + np.asarray(params["hem_phases"])[None])).sum(1)
    return waves / w.sum()


class _HullStack:
    """Radial function of the convex hull of body points between ``z`` and a top height,
    accumulated downwards, on a grid of heights (1 cm) and angles (1 degree)."""

    def __init__(self, points: np.ndarray, center: np.ndarray, z_top: float, z_bottom: float, slack: float = 0.03):
        self.center = center
        self.z = np.arange(z_top, z_bottom - 0.02, -0.01)
        self.theta = np.linspace(0, 2 * np.pi, 361)[:-1]
        radius = np.zeros((len(self.z), len(self.theta)))
        acc = points[(points[:, 2] <= z_top + slack) & (points[:, 2] >= z_top - 0.01), :2]
        for i, z in enumerate(self.z):
            acc = np.concatenate([acc, points[(points[:, 2] < z + 0.01) & (points[:, 2] >= z - 0.01), :2]])
            if len(acc) >= 3:
                radius[i] = convex_radius(acc, center, self.theta)
                acc = acc[ConvexHull(acc).vertices]  # only the hull matters below
            else:
                radius[i] = radius[i - 1] if i else 0.0
        self.radius = radius

    def __call__(self, z: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Hull radius at heights ``z (K,)`` and angles ``theta (K,)``."""
        zi = np.clip((self.z[0] - z) / 0.01, 0, len(self.z) - 1.001)
        i0 = zi.astype(int)
        f = zi - i0
        ti = np.mod(theta, 2 * np.pi) / (2 * np.pi) * len(self.theta)
        j0 = ti.astype(int) % len(self.theta)
        j1 = (j0 + 1) % len(self.theta)
        g = ti - np.floor(ti)
        r0 = self.radius[i0, j0] * (1 - g) + self.radius[i0, j1] * g
        r1 = self.radius[i0 + 1, j0] * (1 - g) + self.radius[i0 + 1, j1] * g
        return r0 * (1 - f) + r1 * f


def _smax(a, b, k):
    """Smooth maximum, never below ``max(a, b)``; equal to it where ``k = 0``."""
    return 0.5 * (a + b + np.sqrt((a - b) ** 2 + k**2))


def _skirt_tube(builder: MeshBuilder, lm: BodyLandmarks, top_ids: np.ndarray, z_w: float, p: dict, h: float):
    """Hang a skirt from the ring ``top_ids`` (at height ``z_w``) down to the hem."""
    center = np.array([0.0, lm.center_y])
    top_theta, top_r = polar(builder.position(top_ids), center)
    order = np.argsort(top_theta)
    top_ids, top_theta, top_r = top_ids[order], top_theta[order], top_r[order]
    length = p["length"]
    z_hem_min = z_w - length - max(p["hem_slope"], 0) - p["hem_irregularity"]
    if z_hem_min < 0.03 or z_w - length + min(p["hem_slope"], 0) > z_w - 0.05:
        raise InputError(
            f"length {length:.2f} m with hem slope {p['hem_slope']:.2f} and irregularity "
            f"{p['hem_irregularity']:.2f} puts the hem below the floor or above the waist (waist at {z_w:.2f} m)"
        )
    hull = _HullStack(lm.verts[lm.torso_mask], center, z_w, z_hem_min)
    tan = np.tan(np.radians(p["flare"]))
    lobes, phase = p["ripple_lobes"], p["ripple_phase"]

    def surface(t: float, theta: np.ndarray) -> np.ndarray:
        r_top = periodic_interp(theta, top_theta, top_r)
        hem = z_w - length - p["hem_slope"] * (1 + np.sin(theta)) / 2 + p["hem_irregularity"] * _hem_waves(theta, p)
        z = z_w + t * (hem - z_w)
        drop = z_w - z
        base = hull(z, theta)
        ease_top = np.maximum(r_top - hull(np.full_like(theta, z_w), theta), 0.005)
        s = _smoothstep(drop / 0.15)
        r = _smax(base + ease_top * (1 - s) + p["hip_ease"] * s, r_top + drop * tan, 0.03 * s)
        r = r + p["ripple"] * (drop / length) ** 1.5 * np.sin(lobes * theta + phase)
        r = np.maximum(r, base + 0.01 * s + ease_top * (1 - s))
        return np.stack([center[0] + r * np.cos(theta), center[1] + r * np.sin(theta), z], 1)

    longest = (length + abs(p["hem_slope"]) + p["hem_irregularity"]) * np.sqrt(1 + tan**2)
    build_tube(builder, top_ids, top_theta, surface, lambda t: center, h, longest, anchors=(-np.pi / 2,))


def _bodice(lm: BodyLandmarks, z_cut: float, p: dict, h: float, sleeves: bool) -> tuple[np.ndarray, np.ndarray]:
    """The upper body piece: the body surface above ``z_cut`` cut to the neckline and sleeves (or
    straps and arm holes), inflated to the ease. Returns ``(verts, faces)``; its lowest boundary
    loop lies at height ``z_cut``."""
    v, f, arm = lm.verts, lm.faces, lm.arm_weight
    a = np.clip(arm.sum(1), 0, 1)
    # Torso below z_cut goes; arms are exempt (their own cuts follow).
    v, f, arm = cut_mesh(v, f, (z_cut - v[:, 2]) * (1 - a) - 0.05 * a, arm)
    neck = lm.joints["neck"][0]
    if sleeves:
        for side in (0, 1):
            w = arm[:, side]
            v, f, arm = cut_mesh(v, f, w * (lm.along_arm(v, side) - p["sleeve_length"]) - (1 - w) * 0.05, arm)
        top = neck[2] + 0.06
        depth = p["neck_depth_back"] + (p["neck_depth_front"] - p["neck_depth_back"]) * _sigmoid(-(v[:, 1] - neck[1]) / 0.02)
        v, f, arm = cut_mesh(v, f, 1 - ((v[:, 0] / p["neck_width"]) ** 2 + ((v[:, 2] - top) / depth) ** 2), arm)
        ease = p["bodice_ease"] * (1 - arm.sum(1)) + p["sleeve_ease"] * arm.sum(1)
    else:
        v, f, arm = cut_mesh(v, f, v[:, 2] - (neck[2] + 0.06), arm)
        front, back = lm.armpit_z + p["top_height_front"], lm.armpit_z + p["top_height_back"]
        top = back + (front - back) * _sigmoid(-(v[:, 1] - lm.center_y) / 0.03)
        band = np.abs(np.abs(v[:, 0]) - p["strap_offset"]) - p["strap_width"] / 2
        v, f, arm = cut_mesh(v, f, np.minimum(v[:, 2] - top, band), arm)
        v, f, arm = cut_mesh(v, f, arm.max(1) - 0.5, arm)
        # Straps sit closer to the shoulders than the bodice to the torso.
        near_top = _smoothstep((v[:, 2] - (lm.armpit_z + 0.02)) / 0.06)
        ease = p["bodice_ease"] * (1 - near_top) + min(p["bodice_ease"], 0.012) * near_top
    labels = face_components(f)
    f = f[labels == np.bincount(labels).argmax()]  # drop the head and hands
    used = np.unique(f)
    remap = np.full(len(v), -1)
    remap[used] = np.arange(len(used))
    v, f, ease = v[used], remap[f], ease[used]
    bottom = _lowest_loop(v, f, lm, z_cut)
    frozen = np.zeros(len(v), bool)
    frozen[bottom] = True
    return inflate(v, f, lm.sdf, ease, frozen_z=frozen), f


def _lowest_loop(v: np.ndarray, f: np.ndarray, lm: BodyLandmarks, z_cut: float) -> np.ndarray:
    """The boundary loop at the waist cut: the one whose centre is nearest the torso axis at ``z_cut``."""
    loops = boundary_loops(f)
    target = np.array([0.0, lm.center_y, z_cut])
    return min(loops, key=lambda loop: np.linalg.norm(v[loop].mean(0) - target))


def _trousers(builder: MeshBuilder, lm: BodyLandmarks, top_ids: np.ndarray, z_w: float, p: dict, h: float):
    """Pelvis tube from the waist ring down to the crotch seam, then two legs."""
    center = np.array([0.0, lm.center_y])
    top_theta, top_r = polar(builder.position(top_ids), center)
    order = np.argsort(top_theta)
    top_ids, top_theta, top_r = top_ids[order], top_theta[order], top_r[order]
    z_c = lm.crotch_z - p["crotch_drop"]
    z_hem = z_c - p["length"]
    if z_hem - p["hem_irregularity"] < 0.03:
        raise InputError(f"leg length {p['length']:.2f} m puts the hem below the floor (crotch seam at {z_c:.2f} m)")
    body = lm.verts[lm.torso_mask]
    hull = _HullStack(body, center, z_w, z_c)

    def pelvis(t: float, theta: np.ndarray) -> np.ndarray:
        z = z_w + t * (z_c - z_w)
        r_top = periodic_interp(theta, top_theta, top_r)
        ease_top = np.maximum(r_top - hull(np.full_like(theta, z_w), theta), 0.005)
        s = _smoothstep((z_w - z) / 0.12)
        # Ease grows towards the leg ease at the crotch so the legs continue without a step.
        low = p["hip_ease"] + (p["leg_ease"] - p["hip_ease"]) * t**2
        r = hull(np.full_like(theta, z), theta) + ease_top * (1 - s) + low * s
        return np.stack([center[0] + r * np.cos(theta), center[1] + r * np.sin(theta), np.full_like(theta, z)], 1)

    ring, ring_theta = build_tube(
        builder, top_ids, top_theta, pelvis, lambda t: center, h, z_w - z_c,
        anchors=(-np.pi / 2,), last_anchors=(-np.pi / 2, np.pi / 2),
    )
    ring_theta = np.mod(ring_theta, 2 * np.pi)
    front = ring[np.argmin(np.abs(np.angle(np.exp(1j * (ring_theta + np.pi / 2)))))]
    back = ring[np.argmin(np.abs(np.angle(np.exp(1j * (ring_theta - np.pi / 2)))))]
    pf, pb = builder.position(np.array([front, back]))
    n_seam = max(1, int(round(abs(pb[1] - pf[1]) / h)))
    seam_pts = pf[None] + (np.arange(1, n_seam) / n_seam)[:, None] * (pb - pf)[None]
    seam = builder.add_verts(seam_pts)  # front to back along x = 0
    left = np.mod(ring_theta + np.pi / 2, 2 * np.pi) <= np.pi + 1e-9  # from front over +X to back
    for side in (1, -1):
        half = ring[left] if side == 1 else ring[~left | np.isin(ring, [front, back])]
        leg_ids = np.concatenate([half, seam[::-1] if side == 1 else seam])
        _leg(builder, lm, body, leg_ids, side, z_c, z_hem, p, h)


def _leg(builder, lm, body, top_ids, side, z_c, z_hem, p, h):
    """One trouser leg below its top ring (half the pelvis ring plus the crotch seam)."""
    pts = body[(side * body[:, 0] > 0) & (body[:, 2] <= z_c + 0.02)]
    thigh = pts[np.abs(pts[:, 2] - z_c) < 0.02]
    c = np.array([thigh[:, 0].mean(), thigh[:, 1].mean()])
    top_theta, top_r = polar(builder.position(top_ids), c)
    order = np.argsort(top_theta)
    top_ids, top_theta, top_r = top_ids[order], top_theta[order], top_r[order]
    hull = _HullStack(pts, c, z_c, z_hem - p["hem_irregularity"], slack=0.02)
    tan = np.tan(np.radians(p["leg_flare"]))

    def surface(t: float, theta: np.ndarray) -> np.ndarray:
        hem = z_hem + p["hem_irregularity"] * _hem_waves(theta, p)
        z = z_c + t * (hem - z_c)
        drop = z_c - z
        s = _smoothstep(drop / 0.15)
        target = hull(z, theta) + p["leg_ease"] + drop * tan
        r = periodic_interp(theta, top_theta, top_r) * (1 - s) + target * s
        x = c[0] + r * np.cos(theta)
        inner = p["leg_gap"] / 2 * _smoothstep(drop / 0.05)
        x = side * np.maximum(side * x, inner)
        return np.stack([x, c[1] + r * np.sin(theta), z], 1)

    build_tube(builder, top_ids, top_theta, surface, lambda t: c, h, z_c - z_hem + p["hem_irregularity"])


def _pinned(verts: np.ndarray, kind: str, lm: BodyLandmarks, z_w: float, h: float) -> np.ndarray:
    """Waistband ring (skirt, jumpsuit) and shoulder / strap tops (dress, long shirt, jumpsuit)."""
    band = max(0.02, 1.5 * h)
    pinned = np.zeros(len(verts), bool)
    if kind == "skirt":
        pinned |= verts[:, 2] > z_w - band
    if kind == "jumpsuit":
        pinned |= np.abs(verts[:, 2] - z_w) < band / 2
    if kind in ("dress", "long_shirt", "jumpsuit"):
        _, _, face = lm.sdf.closest(verts)
        up = lm.sdf.face_normals[face][:, 2]
        shoulder_x = lm.joints["shoulder"][0][0]
        pinned |= (up > 0.6) & (verts[:, 2] > lm.armpit_z + 0.08) & (np.abs(verts[:, 0]) < shoulder_x + 0.01)
    return pinned


def make_garment(kind: str, body: BodyModel, seed: int = 0, edge_length: float = 0.02, **params) -> Garment:
    """Make a garment of a template kind fitted to ``body`` in its rest pose.

    Args:
        kind: one of :data:`KINDS`.
        body: the body (its own shape, rest pose).
        seed: draws every parameter not given.
        edge_length: target edge length in metres (:data:`EDGE_LENGTH_RANGE`); the vertex count is
            about ``area / (0.866 * edge_length**2)`` (equilateral triangles, 2 per vertex), e.g.
            ~3k for a knee-length skirt at 0.02 m.
        **params: values for any of ``PARAMS[kind]``.

    Returns:
        A :class:`Garment`: one connected, edge-manifold, outward-oriented triangle mesh at least
        :data:`CLEARANCE` from the body at every vertex and edge midpoint, with ``pinned`` set.

    Raises:
        InputError: unknown kind or parameter, a value out of range, a hem below the floor.
    """
    lo, hi = EDGE_LENGTH_RANGE
    if not lo <= edge_length <= hi:
        raise InputError(f"edge_length {edge_length} m is outside [{lo}, {hi}]")
    p = draw_params(kind, seed, **params)
    lm = measure_body(body)
    h = float(edge_length)
    z_w = lm.waist_z + p["waist_offset"]
    # Drawn values are fitted to the body (the hem stays 5 cm above the floor); given ones are checked.
    top = lm.crotch_z - p["crotch_drop"] if kind == "jumpsuit" else z_w
    if "length" not in params:
        p["length"] = float(min(p["length"], top - 0.05 - p["hem_irregularity"] - max(p.get("hem_slope", 0.0), 0.0)))
    else:
        room = max(top - 0.05 - p["length"], 0.0)
        for name in ("hem_slope", "hem_irregularity"):
            if name in p and name not in params and p[name] > room:
                p[name] = float(room)
            room -= max(p.get(name, 0.0), 0.0)
    if kind == "skirt":
        center = np.array([0.0, lm.center_y])
        hull = _HullStack(lm.verts[lm.torso_mask], center, z_w, z_w - 0.02)
        builder = MeshBuilder()
        theta = np.linspace(0, 2 * np.pi, 721)[:-1]
        r = hull(np.full_like(theta, z_w), theta) + p["waist_ease"]
        ring = np.stack([center[0] + r * np.cos(theta), center[1] + r * np.sin(theta), np.full_like(theta, z_w)], 1)
        count = max(8, int(round(np.linalg.norm(np.diff(ring, axis=0, append=ring[:1]), axis=1).sum() / h)))
        ang = -np.pi / 2 + 2 * np.pi * np.arange(count) / count
        r_ang = periodic_interp(ang, theta, r)
        top = builder.add_verts(
            np.stack([center[0] + r_ang * np.cos(ang), center[1] + r_ang * np.sin(ang), np.full_like(ang, z_w)], 1)
        )
        _skirt_tube(builder, lm, top, z_w, p, h)
    else:
        sleeves = kind == "long_shirt" or (kind == "dress" and p["sleeve_length"] > 0)
        bv, bf = _bodice(lm, z_w, p, h, sleeves)
        builder = MeshBuilder(bv, bf)
        bottom = _lowest_loop(bv, bf, lm, z_w)
        if kind == "jumpsuit":
            _trousers(builder, lm, bottom, z_w, p, h)
        else:
            _skirt_tube(builder, lm, bottom, z_w, p, h)
    verts, faces = builder.mesh()
    faces = orient_outward(verts, faces, lm.sdf)
    surface = ReferenceSurface(verts, faces, spacing=h / 20)
    verts, faces = remesh(verts, faces, h, iterations=5, surface=surface)
    verts = push_out(verts, faces, lm.sdf, CLEARANCE * 1.2)
    verts, faces = clean_up(verts, faces, h)
    verts = push_out(verts, faces, lm.sdf, CLEARANCE * 1.2)
    report = mesh_report(verts, faces)
    if not report.ok:
        raise RuntimeError(f"{kind} seed {seed}: template mesh is broken: {report}")
    pinned = _pinned(verts, kind, lm, z_w, h)
    p["edge_length"] = h
    return Garment(verts=verts, faces=faces, pinned=pinned, kind=kind, params=p, name=f"{kind}-{seed}",
                   body_shape=shape_record(getattr(body, "shape", None)))
