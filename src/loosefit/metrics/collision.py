"""Garment-body collision ratio (SwinGar, Li et al. 2024, Table II).

A garment vertex collides when its signed distance to the body is below ``-tolerance`` (inside the
body by more than the tolerance); the ratio is ``100 * colliding / V`` per frame, in percent, and
the ratio of a sequence is the mean over its frames (every frame has the same ``V``).

The body is given either as a :class:`~loosefit.geometry.signed_distance.BodySDF` (one static body
for every frame), a list of ``T`` of them, or as body vertices ``(Vb, 3)`` / ``(T, Vb, 3)`` with faces
(a posed body sequence; one AABB tree is built per frame). The default tolerance of 1 mm ignores
vertices resting on the skin within simulation round-off.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from loosefit.errors import InputError
from loosefit.geometry.laplacian import edges
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
    v = np.asarray(garment_verts, np.float64)
    f = np.asarray(faces, np.int64)
    e = edges(f)
    return np.concatenate([(v[..., e[:, 0], :] + v[..., e[:, 1], :]) / 2, v[..., f, :].mean(-2)], axis=-2)


#: Depth (metres) beyond which an animated garment vertex counts as inside the body in what ``loosefit animate``
#: reports: deeper than cloth resting on the skin, shallower than the collisions a user sees.
REPORT_DEPTH = 0.005
#: Frames (evenly spaced) ``loosefit animate`` measures: the proxy's distance costs about 50 ms a frame.
REPORT_FRAMES = 60


def inside_body_report(garment_verts: np.ndarray, body, motion, depth: float = REPORT_DEPTH,
                       max_frames: int = REPORT_FRAMES) -> dict:
    """How much of an animated garment is inside the body, as ``loosefit animate`` prints it.

    Args:
        garment_verts: ``(T, V, 3)`` world garment vertices along ``motion``, metres.
        body: the body the garment is worn on, measured at its full resolution: the collision handling corrects
            against a coarser proxy that lies up to about a centimetre inside it, so the proxy would under-report.
        depth: metres inside the body a vertex must exceed to count.
        max_frames: frames measured at most, evenly spaced over the motion.

    Returns:
        ``{"mean_percent", "worst_percent", "frames", "of_frames", "depth_m"}``: the percentage of vertices
        deeper than ``depth`` averaged over the measured frames and in the worst one.
    """
    T = len(garment_verts)
    frames = np.unique(np.linspace(0, T - 1, min(T, max_frames)).round().astype(int))
    posed = body.pose(dataclasses.replace(motion, rotations=motion.rotations[frames],
                                         translation=motion.translation[frames])).verts
    ratio = collision_ratio_per_frame(np.asarray(garment_verts)[frames], posed, body.faces, depth)
    return {"mean_percent": float(ratio.mean()), "worst_percent": float(ratio.max()), "frames": int(len(frames)),
            "of_frames": int(T), "depth_m": depth}

