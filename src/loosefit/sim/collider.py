"""The collision body Blender's cloth collides with: the body's low-resolution proxy, inflated to enclose the full body.

It also sets how finely Blender must step: cloth-body contacts are found by proximity, so the
body must not move much more than the collision distance within one solver step
(:func:`steps_per_frame`).

The decimated proxy (1,229 vertices) lies up to about 1 cm inside the full-resolution surface
(chest, hips, calves), so cloth resting on it would sink into the full body that the quality gate
measures. Each proxy vertex is therefore pushed out along its normal, in the rest pose, by the
largest distance by which the full-body vertices nearest to it stick out of the proxy; the
inflated proxy is then posed with the proxy's own skinning.
"""

from __future__ import annotations

import weakref

import igl
import numpy as np
from scipy.spatial import cKDTree

from loosefit.body.base import BodyModel
from loosefit.geometry.normals import vertex_normals
from loosefit.motion.motion import Motion
from loosefit.sim.attach import skin_garment


def inflated_rest(body: BodyModel, proxy: BodyModel, shape=None) -> np.ndarray:
    """``(Vp, 3)`` float32 rest vertices of ``proxy`` pushed out so that ``body`` (full resolution) is inside."""
    low = proxy.rest_verts(shape).astype(np.float64)
    return (low + _rest_push(body, proxy, shape)[0][:, None] * vertex_normals(low, proxy.faces)).astype(np.float32)


def _rest_push(body: BodyModel, proxy: BodyModel, shape=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(push (Vp,), nearest (Vb,), face (Vb,))``: the largest distance, m, by which the full-body rest vertices
    nearest to each proxy vertex lie outside the rest proxy (0 when none does), each full-body vertex's nearest
    proxy vertex, and the proxy triangle closest to it."""
    full = body.rest_verts(shape).astype(np.float64)
    low = proxy.rest_verts(shape).astype(np.float64)
    outside, face = igl.signed_distance(full, low, proxy.faces, igl.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER)[:2]
    _, nearest = cKDTree(low).query(full)
    push = np.zeros(len(low))
    np.maximum.at(push, nearest, outside)
    return push, nearest, face


def enclosing_frames(body: BodyModel, motion: Motion, within: np.ndarray | None = None,
                     margin: float = 0.02) -> np.ndarray:
    """The posed collision proxy pushed out, frame by frame, so that the posed full-resolution body is inside it.

    The rest-pose push of :func:`inflated_rest` does not hold in every pose: the two meshes are skinned with
    their own weights, and on a walk the full body's lower back bulges up to 13 mm out of the posed proxy where
    it lies within 2 mm at rest. Here each proxy vertex moves out along its posed normal by the largest distance
    by which the posed full-body vertices nearest to it (at rest) lie outside the posed proxy (their height above
    the plane of the proxy triangle closest to them at rest).

    Args:
        body: the full-resolution body; motion: ``T`` frames on its rig.
        within: ``(T, N, 3)`` points (a garment) whose box, widened by ``margin`` metres, limits the full-body
            vertices looked at in each frame (a proxy vertex with none of its full-body vertices there keeps the rest
            pose's push); ``None``: all of them.

    Returns:
        ``(T, Vp, 3)`` float32 vertices on the proxy's faces.
    """
    proxy = body.collision_proxy()
    faces = np.asarray(proxy.faces, np.int64)
    # Each full-body vertex is measured against the plane of the proxy triangle closest to it at rest: exact
    # while that triangle stays the closest, and a tenth of the cost of a closest-point query per frame.
    rest_push, nearest, face = _rest_push_cached(body, proxy)
    order = np.argsort(nearest, kind="stable")  # the full-body vertices grouped by their proxy vertex
    owner, first = np.unique(nearest[order], return_index=True)
    posed_full, posed_low = body.pose(motion).verts, proxy.pose(motion).verts
    out = np.empty(posed_low.shape, np.float32)
    for start in range(0, len(posed_low), _ENCLOSING_CHUNK):  # frames at once, a few MB each
        frames = slice(start, start + _ENCLOSING_CHUNK)
        v, full = posed_low[frames].astype(np.float64), posed_full[frames]
        tri = v[:, faces]
        side = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])
        side /= np.maximum(np.linalg.norm(side, axis=-1, keepdims=True), 1e-12)
        # the height of each full-body vertex above its rest-closest proxy triangle's plane
        distance = np.einsum("tnd,tnd->tn", full - tri[:, face, 0], side[:, face])
        if within is not None:  # only the full-body vertices within the garment's box count
            lo = within[frames].min(1, keepdims=True) - margin
            hi = within[frames].max(1, keepdims=True) + margin
            distance[~((full >= lo) & (full <= hi)).all(-1)] = -np.inf
        seen = np.full(v.shape[:2], -np.inf)
        seen[:, owner] = np.maximum.reduceat(distance[:, order], first, axis=1)
        push = np.where(np.isfinite(seen), np.maximum(seen, 0.0), rest_push)
        out[frames] = v + push[..., None] * vertex_normals(v, faces)
    return out


#: Frames :func:`enclosing_frames` measures at once.
_ENCLOSING_CHUNK = 16

#: ``(shape, _rest_push)`` of the bodies seen, by body object: about 0.1 s a call (1.3 ms a frame of a 3 s clip).
_REST_PUSH: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _rest_push_cached(body: BodyModel, proxy: BodyModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_rest_push` of ``body`` (its own shape), computed again only for another body object or shape."""
    shape = getattr(body, "shape", None)
    try:
        seen, value = _REST_PUSH[body]
        if seen is shape:
            return value
    except (KeyError, TypeError):
        pass
    value = _rest_push(body, proxy)
    try:
        _REST_PUSH[body] = (shape, value)
    except TypeError:  # not weakly referable: not cached
        pass
    return value


def collider_frames(body: BodyModel, motion: Motion, shape=None, kind: str = "proxy") -> tuple[np.ndarray, np.ndarray]:
    """The collision body along ``motion``.

    Args:
        body: the full-resolution body.
        motion: ``T`` frames on its rig.
        shape: body shape (``None`` for the body's own).
        kind: ``"proxy"`` (inflated low-resolution proxy) or ``"full"`` (the body itself).

    Returns:
        ``(verts (T, Vc, 3) float32, faces (Fc, 3) int64)``.
    """
    if kind == "full":
        return body.pose(motion, shape).verts, body.faces
    proxy = body.collision_proxy()
    rest = inflated_rest(body, proxy, shape)
    return skin_garment(rest, proxy.skinning_weights(), proxy, motion, shape), proxy.faces


#: Body surface travel allowed per solver step, in collision distances. At 2 a 7k-vertex skirt on a
#: two-turns-per-second spin (body 12 cm per frame near the skirt: 16 steps) stays out of the body;
#: with 8 steps 7% of its vertices went through.
TRAVEL_PER_STEP = 2.0
#: The same for the Newton backend. Its contact is a barrier on the unsigned distance to the body
#: triangles, acting within one collision distance and holding resting cloth about that far out;
#: a body triangle that moves further within one step passes the cloth vertex, which is then
#: pushed out on the wrong side. Measured on a box rising into a cloth
#: (tests/sim/test_backends.py): 0.93 collision distances per step kept the cloth out, 1.24 let
#: the box through; 0.75 leaves a margin.
NEWTON_TRAVEL_PER_STEP = 0.75


def travel_per_step(backend: str) -> float:
    """Body travel allowed per solver step, in collision distances, for a simulation backend."""
    return NEWTON_TRAVEL_PER_STEP if backend == "newton" else TRAVEL_PER_STEP


#: Never more solver steps per frame than this.
MAX_STEPS = 64


def steps_per_frame(
    collider: np.ndarray,
    garment: np.ndarray,
    collision_distance: float,
    minimum: int,
    near: float = 0.1,
    travel_per_step: float = TRAVEL_PER_STEP,
) -> int:
    """Solver steps per frame so that the collider near the garment moves at most
    ``travel_per_step * collision_distance`` per step (at least ``minimum``, at most ``MAX_STEPS``).

    Args:
        collider: ``(N, Vc, 3)`` collider vertices per frame.
        garment: ``(V, 3)`` garment at frame 0; collider vertices within ``near`` metres of it count.
        collision_distance: m.
        minimum: the fewest steps.
        near: m.
        travel_per_step: allowed travel per step in collision distances (:data:`TRAVEL_PER_STEP`
            for Blender, :data:`NEWTON_TRAVEL_PER_STEP` for Newton).
    """
    close = cKDTree(garment).query(collider[0], distance_upper_bound=near)[0] < near
    if len(collider) < 2 or not close.any():
        return minimum
    travel = float(np.linalg.norm(np.diff(collider[:, close], axis=0), axis=-1).max())
    return int(np.clip(np.ceil(travel / (travel_per_step * collision_distance)), minimum, MAX_STEPS))
