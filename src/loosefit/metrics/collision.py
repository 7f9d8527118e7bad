"""Garment-body collision ratio (SwinGar, Li et al. 2024, Table II).

A garment vertex collides when its signed distance to the body is below ``-tolerance`` (inside the
body by more than the tolerance); the ratio is ``100 * colliding / V`` per frame, in percent, and
the ratio of a sequence is the mean over its frames (every frame has the same ``V``).

The body is given either as a :class:`~loosefit.geometry.signed_distance.BodySDF` (one static body
for every frame), a list of ``T`` of them, or as body vertices ``(Vb, 3)`` / ``(T, Vb, 3)`` with faces
(a posed body sequence; one AABB tree is built per frame). The default tolerance of 1 mm ignores
vertices resting on the skin within simulation round-off.

A limb can pass between vertices that all stay outside it, so penetration is also measured on the surface
(:func:`penetration`): at every edge's midpoint and every triangle's centroid (:func:`surface_samples`), the share
of them deeper than a depth (5 mm by default, :data:`REPORT_DEPTH`), and the deepest point, vertices and samples
together. One distance query a frame serves all of them, and several garments on one body (:func:`penetrations`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from loosefit.errors import InputError
from loosefit.geometry.laplacian import check_mesh, edges
from loosefit.geometry.signed_distance import BodySDF, PosedBodySDF, posed_body_sdfs  # noqa: F401 - PosedBodySDF re-exported

DEFAULT_TOLERANCE = 1e-3


def _body_sdfs(body, body_faces, num_frames: int):
    if isinstance(body, BodySDF):
        return [body] * num_frames
    if isinstance(body, Sequence) and len(body) and all(isinstance(b, BodySDF) for b in body):
        if len(body) != num_frames:
            raise InputError(f"got {len(body)} body SDFs for {num_frames} garment frames")
        return list(body)
    verts = np.asarray(body, dtype=np.float64)
    if body_faces is None:
        raise InputError("body vertices need body faces")
    if verts.ndim == 2:
        return [BodySDF(verts, body_faces)] * num_frames
    if verts.ndim != 3 or len(verts) != num_frames:
        raise InputError(f"body vertices must be (Vb, 3) or ({num_frames}, Vb, 3), got {verts.shape}")
    return posed_body_sdfs(verts, body_faces)


def collision_mask(garment_verts: np.ndarray, body, body_faces: np.ndarray | None = None, tolerance: float = DEFAULT_TOLERANCE) -> np.ndarray:
    """``(T, V)`` bool: garment vertex inside the body deeper than ``tolerance`` metres.

    Args:
        garment_verts: ``(T, V, 3)`` or ``(V, 3)`` garment positions, metres.
        body: a ``BodySDF``, a list of ``T`` of them, or body vertices ``(Vb, 3)`` / ``(T, Vb, 3)``.
        body_faces: ``(Fb, 3)`` body triangles, needed when ``body`` is vertices.
        tolerance: depth in metres (>= 0) a vertex must exceed to count.
    """
    g = np.asarray(garment_verts, dtype=np.float64)
    if g.ndim == 2:
        g = g[None]
    if g.ndim != 3 or g.shape[2] != 3 or not np.isfinite(g).all():
        raise InputError(f"garment vertices must be finite (T, V, 3), got shape {g.shape}")
    if not tolerance >= 0:
        raise InputError(f"collision tolerance must be >= 0 metres, got {tolerance}")
    sdfs = _body_sdfs(body, body_faces, len(g))
    return np.stack([sdf.query(frame) < -tolerance for sdf, frame in zip(sdfs, g)])


def collision_ratio_per_frame(garment_verts, body, body_faces=None, tolerance: float = DEFAULT_TOLERANCE) -> np.ndarray:
    """``(T,)`` percentage of garment vertices inside the body beyond ``tolerance``."""
    return 100.0 * collision_mask(garment_verts, body, body_faces, tolerance).mean(1)


def collision_ratio(garment_verts, body, body_faces=None, tolerance: float = DEFAULT_TOLERANCE) -> float:
    """Mean over frames of the colliding-vertex percentage."""
    return float(collision_ratio_per_frame(garment_verts, body, body_faces, tolerance).mean())


def surface_samples(garment_verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Points on the garment's surface between its vertices: every edge's midpoint and every triangle's centroid,
    ``(..., E + F, 3)`` for ``garment_verts (..., V, 3)``. A limb can pass between vertices that are all outside it
    (a triangle spanning the limb); measured at these points, the collision ratio sees it."""
    f = np.asarray(faces, np.int64)
    return _samples(np.asarray(garment_verts, np.float64), f, edges(f))


def _samples(v: np.ndarray, f: np.ndarray, e: np.ndarray) -> np.ndarray:
    return np.concatenate([(v[..., e[:, 0], :] + v[..., e[:, 1], :]) / 2, v[..., f, :].mean(-2)], axis=-2)


#: Depth (metres) beyond which an animated garment vertex counts as inside the body in what ``loosefit animate``
#: reports: deeper than cloth resting on the skin, shallower than the collisions a user sees.
REPORT_DEPTH = 0.005
#: Frames (evenly spaced) ``loosefit animate`` measures: the proxy's distance costs about 50 ms a frame.
REPORT_FRAMES = 60


@dataclass
class Penetration:
    """How deep one garment sequence of ``T`` frames is inside the body, frame by frame.

    Attributes:
        vertex_percent: ``(T,)`` percent of the ``V`` vertices deeper than the tolerance.
        surface_percent: ``(T,)`` percent of the ``S = E + F`` surface samples (:func:`surface_samples`: edge
            midpoints and triangle centroids) deeper than the depth.
        deepest_m: ``(T,)`` metres: the deepest point inside the body, vertices and samples together; 0 where none
            is inside.
        samples: ``S``, the number of surface samples a frame (the weight of ``surface_percent`` when pooling).
    """

    vertex_percent: np.ndarray
    surface_percent: np.ndarray
    deepest_m: np.ndarray
    samples: int


def penetrations(garments: Sequence[tuple[np.ndarray, np.ndarray]], body, body_faces: np.ndarray | None = None,
                 tolerance: float = DEFAULT_TOLERANCE, depth: float = REPORT_DEPTH) -> list[Penetration]:
    """:class:`Penetration` of several garments on one body (several methods' predictions of one motion): the
    body's distance field is built once a frame (most of the time on a posed body: about 58 ms a frame for the Anny
    body) and serves the vertices and surface samples of all of them.

    A sample is queried only where it could count: the signed distance of a closed mesh changes by at most the
    distance moved, so a sample ``p`` between vertices ``v_i`` is at least ``max_i (sdf(v_i) - |p - v_i|)``
    outside; where that bound shows it neither deeper than ``depth`` nor deeper than the deepest vertex, it is
    skipped (most of a garment away from the skin). The counts and depths are those of querying every sample;
    measured on a 5,000-vertex cylinder through a walking Anny body (8 % of it inside), 60 frames took 8.7 s
    against 17.0 s querying every sample and 7.6 s for the vertices alone (the shared 2-core machine).

    Args:
        garments: ``(verts (T, V_k, 3), faces (F_k, 3))`` per garment, metres, all with the same ``T``.
        body: a ``BodySDF``, a list of ``T`` of them, or body vertices ``(Vb, 3)`` / ``(T, Vb, 3)``.
        body_faces: ``(Fb, 3)`` body triangles, needed when ``body`` is vertices.
        tolerance: metres (>= 0) a vertex must be inside to count in ``vertex_percent``.
        depth: metres (>= 0) a surface sample must be inside to count in ``surface_percent``.
    """
    if not tolerance >= 0 or not depth >= 0:
        raise InputError(f"collision tolerance and depth must be >= 0 metres, got {tolerance} and {depth}")
    meshes = []
    for verts, faces in garments:
        g = np.asarray(verts, dtype=np.float64)
        if g.ndim == 2:
            g = g[None]
        if g.ndim != 3 or g.shape[2] != 3 or not np.isfinite(g).all():
            raise InputError(f"garment vertices must be finite (T, V, 3), got shape {g.shape}")
        _, f = check_mesh(g[:1], faces)
        meshes.append((g, f, edges(f)))
    if not meshes:
        return []
    T = len(meshes[0][0])
    if any(len(g) != T for g, _, _ in meshes):
        raise InputError(f"garments of {sorted({len(g) for g, _, _ in meshes})} frames on one body")
    vertex_bounds = np.cumsum([0] + [g.shape[1] for g, _, _ in meshes])
    vertex, surface, deepest = (np.zeros((len(meshes), T)) for _ in range(3))
    for t, sdf in enumerate(_body_sdfs(body, body_faces, T)):
        # float32 distances and comparisons, as collision_mask's
        at_vertices = -sdf.query(np.concatenate([g[t] for g, _, _ in meshes]))  # depth inside, m (< 0 outside)
        wanted = []
        for k, (g, f, e) in enumerate(meshes):
            inside = at_vertices[vertex_bounds[k]:vertex_bounds[k + 1]]
            vertex[k, t] = 100.0 * (inside > tolerance).mean()
            deepest[k, t] = max(0.0, float(inside.max()))
            # samples a frame at a time: every frame's samples of a 10k-vertex garment would be 60k x T points
            points, most = _samples(g[t], f, e), _deepest_possible(g[t], f, e, inside)
            wanted.append(points[most > min(depth, deepest[k, t]) - _SLACK])
        at_samples = -sdf.query(np.concatenate(wanted)) if sum(map(len, wanted)) else np.zeros(0, np.float32)
        start = 0
        for k, (g, f, e) in enumerate(meshes):
            inside, start = at_samples[start:start + len(wanted[k])], start + len(wanted[k])
            surface[k, t] = 100.0 * (inside > depth).sum() / (len(e) + len(f))
            deepest[k, t] = max(deepest[k, t], float(inside.max(initial=0.0)))
    return [Penetration(vertex[k], surface[k], deepest[k], len(e) + len(f)) for k, (_, f, e) in enumerate(meshes)]


#: Metres a sample's depth bound is widened by: the float32 distances' round-off, far below any depth reported.
_SLACK = 1e-5


def _deepest_possible(v: np.ndarray, f: np.ndarray, e: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """``(E + F,)`` the most each surface sample (:func:`_samples`'s order) of ``v (V, 3)`` can be inside the body,
    metres, from the vertices' depths ``inside (V,)``: ``min_i (inside_i + |p - v_i|)`` over the sample's vertices."""
    inside = inside.astype(np.float64)
    half = np.linalg.norm(v[e[:, 1]] - v[e[:, 0]], axis=-1) / 2
    at_edges = np.minimum(inside[e[:, 0]], inside[e[:, 1]]) + half
    corners = v[f]  # (F, 3, 3)
    reach = np.linalg.norm(corners - corners.mean(1, keepdims=True), axis=-1)
    at_centroids = (inside[f] + reach).min(1)
    return np.concatenate([at_edges, at_centroids])


def penetration(garment_verts: np.ndarray, faces: np.ndarray, body, body_faces: np.ndarray | None = None,
                tolerance: float = DEFAULT_TOLERANCE, depth: float = REPORT_DEPTH) -> Penetration:
    """:class:`Penetration` of one garment ``garment_verts (T, V, 3)`` on ``faces (F, 3)``; the arguments as in
    :func:`penetrations`."""
    return penetrations([(garment_verts, faces)], body, body_faces, tolerance, depth)[0]


def inside_body_report(garment_verts: np.ndarray, body, motion, depth: float = REPORT_DEPTH,
                       max_frames: int = REPORT_FRAMES, faces: np.ndarray | None = None) -> dict:
    """How much of an animated garment is inside the body, as ``loosefit animate`` prints it.

    Args:
        garment_verts: ``(T, V, 3)`` world garment vertices along ``motion``, metres.
        body: the body the garment is worn on, measured at its full resolution: the collision handling corrects
            against a coarser proxy that lies up to about a centimetre inside it, so the proxy would under-report.
        depth: metres inside the body a vertex or surface sample must exceed to count.
        max_frames: frames measured at most, evenly spaced over the motion.
        faces: ``(F, 3)`` garment triangles: with them the surface between the vertices is measured too.

    Returns:
        ``{"mean_percent", "worst_percent", "surface_mean_percent", "surface_worst_percent", "deepest_mm",
        "frames", "of_frames", "depth_m"}``: the percentage of vertices deeper than ``depth`` averaged over the
        measured frames and in the worst one, the same of the surface samples (edge midpoints and triangle
        centroids, :func:`surface_samples`; ``None`` without ``faces``), and the deepest point of the measured
        frames in millimetres (vertices and samples; 0 when none is inside).
    """
    T = len(garment_verts)
    frames = np.unique(np.linspace(0, T - 1, min(T, max_frames)).round().astype(int))
    posed = body.pose(dataclasses.replace(motion, rotations=motion.rotations[frames],
                                         translation=motion.translation[frames])).verts
    garment = np.asarray(garment_verts)[frames]
    surface = None
    if faces is None:
        inside = -np.stack([sdf.query(g) for sdf, g in zip(posed_body_sdfs(posed, body.faces), garment)])
        ratio = 100.0 * (inside > depth).mean(1)
        deepest = max(0.0, float(inside.max()))
    else:
        found = penetration(garment, faces, posed, body.faces, tolerance=depth, depth=depth)
        ratio, surface, deepest = found.vertex_percent, found.surface_percent, float(found.deepest_m.max())
    return {"mean_percent": float(ratio.mean()), "worst_percent": float(ratio.max()),
            "surface_mean_percent": None if surface is None else float(surface.mean()),
            "surface_worst_percent": None if surface is None else float(surface.max()),
            "deepest_mm": 1000.0 * deepest, "frames": int(len(frames)), "of_frames": int(T), "depth_m": depth}

