"""Collision handling of an animated garment, frame by frame or over a whole motion, with the resolver of
:mod:`loosefit.models.collision.resolver` (SwinGar Eq. 10 and the surface pass) or the push-out baseline.

- :func:`correct_frame` (one frame, for streaming), :func:`correct_motion` (a whole motion) and
  :func:`handle_motion_collisions` (any method's animated garment, ``loosefit animate --collision``): the posed
  collision proxy's :class:`~loosefit.geometry.ray_cull.AxisRayCuller` first proves most vertices outside (an
  axis-aligned ray that meets no triangle facing back along it), and only the others reach the field. Over a
  motion, :data:`FRAME_CHUNK` frames go through each step at once (the cull's kernels launched once,
  :class:`~loosefit.models.collision.fast_eval.MotionBodySDF`, :meth:`CollisionResolver.frames`), and chunks
  run in two threads (the kernels, torch and NumPy release Python's lock).
- :func:`post_process`: the exact field or the push-out baseline on a whole motion, by name
  (:data:`POST_PROCESSES`).

With the exact field the cull changes nothing (beyond float rounding); with the network, a vertex it wrongly
calls inside but that the cull proves outside is not moved. Timings: ``benchmarks/README.md``.
"""

from __future__ import annotations

import queue
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry import warp_sdf
from loosefit.geometry.normals import angle_weighted_normals
from loosefit.geometry.ray_cull import AxisRayCuller
from loosefit.geometry.signed_distance import posed_body_sdfs
from loosefit.models.collision.fast_eval import FramedSDF, MotionBodySDF
from loosefit.models.collision.network import BodySDFNet, SDFFunction, motion_sdf_inputs
from loosefit.models.collision.resolver import SURFACE_PASSES, CollisionResolver, ExactMotionSDF, ExactSDF, push_out
from loosefit.sim.attach import body_lbs
from loosefit.sim.collider import enclosing_frames
from loosefit.threads import torch_threads


#: Bin side of the cull (:class:`~loosefit.geometry.ray_cull.AxisRayCuller`), metres. Finer bins leave fewer
#: candidates but cost more to rasterise; over a motion 1.25 cm was as fast as 2 cm or faster
#: (benchmarks/experiments/LOG.md).
#: With a margin, fewer candidates also means fewer vertices moved that the cull could have proved outside.
CULL_CELL = 0.0125


def correct_frame(verts: np.ndarray, resolver: CollisionResolver, sdf: SDFFunction, frame=None,
                  culler: AxisRayCuller | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Collision handling of one world frame: SwinGar Eq. 10 where the garment may be inside the body, then the
    resolver's surface pass (if it has one on) between the vertices.

    Args:
        verts: ``(V, 3)`` world garment vertices, metres.
        resolver: the garment's :class:`CollisionResolver`.
        sdf: the field, in its own frame (:meth:`BodySDFNet.bind` in the canonical frame, :class:`ExactSDF`).
        frame: ``(rot (3, 3), origin (3,))``: the field's frame, ``p_sdf = (p - origin) @ rot``; None: the world.
        culler: the posed collision body's :class:`~loosefit.geometry.ray_cull.AxisRayCuller`, updated to this
            frame: the vertices and surface samples it proves outside are never given to the field (they could
            not be moved anyway); None: every one is evaluated.

    Returns:
        ``(V, 3)`` float32 corrected world vertices and the ``(V,)`` bool mask of the vertices moved.
    """
    world = np.ascontiguousarray(verts, np.float32)
    candidates = None if culler is None else ~culler.outside(world)
    if frame is not None:
        sdf = FramedSDF(sdf, *frame)
    out, inside = resolver(torch.from_numpy(world), sdf, candidates, None if culler is None else culler.outside)
    return out.numpy(), inside.numpy()


#: Frames corrected in one pass of the network by :func:`correct_motion`: enough that Python's per-call overhead
#: is paid rarely, few enough that a chunk's ``(T V, 3)`` arrays stay small and a short motion still gives both
#: workers a chunk.
FRAME_CHUNK = 32


def correct_motion(verts: np.ndarray, resolver: CollisionResolver, net: "BodySDFNet", code, rot, origin,
                   posed: np.ndarray | None = None, culler: AxisRayCuller | None = None, margin: float = 0.0,
                   workers: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """SwinGar Eq. 10 with the network on every frame of an animated garment (and the resolver's surface pass),
    :data:`FRAME_CHUNK` frames a pass (:class:`MotionBodySDF`, :meth:`CollisionResolver.frames`): what
    :func:`correct_frame` gives frame by frame, up to float rounding.

    Args:
        verts: ``(T, V, 3)`` world garment vertices, metres.
        resolver: the garment's :class:`CollisionResolver`.
        net: the body SDF network; ``code (T, C)``, ``rot (T, 3, 3)``, ``origin (T, 3)``: its inputs per frame
            (:func:`motion_sdf_inputs`).
        posed, culler: the posed collision proxy ``(T, Vb, 3)`` and its
            :class:`~loosefit.geometry.ray_cull.AxisRayCuller`: only the vertices it cannot prove outside reach
            the network; None: every vertex does.
        margin: metres, the network's surface moved outwards (:meth:`BoundBodySDF.offset`).
        workers: threads correcting chunks side by side (Warp's kernels, torch and NumPy's large operations run
            without Python's lock, so two use two cores; each has its own culler and one torch thread); 1: one
            chunk after another, with torch's thread count as it is.

    Returns:
        ``(T, V, 3)`` float32 corrected vertices and the ``(T, V)`` bool mask of the vertices moved.
    """
    if workers < 1:
        raise InputError(f"collision workers must be >= 1, got {workers}")
    world = np.array(verts, np.float32, copy=True)
    T = len(world)
    inside = np.zeros(world.shape[:2], bool)
    if resolver.sigma is None and T:  # set before the threads share the resolver
        resolver.sigma = resolver.mean_edge(torch.from_numpy(world[0]))
    chunks = [slice(s, min(s + FRAME_CHUNK, T)) for s in range(0, T, FRAME_CHUNK)]
    workers = min(workers, len(chunks)) or 1
    cullers = queue.SimpleQueue()  # one culler (its map buffers) per running chunk
    for k in range(workers if culler is not None else 0):
        cullers.put(culler if k == 0 else culler.twin())

    def correct(chunk: slice) -> None:  # frames of one chunk, written in place (chunks do not overlap)
        field = MotionBodySDF(net, code[chunk], rot[chunk], origin[chunk]).offset(margin)
        if culler is None:
            cand = np.ones((chunk.stop - chunk.start, world.shape[1]), bool)
            moved, hit = resolver.frames(torch.from_numpy(world[chunk]), field, cand)
        else:
            mine = cullers.get()  # held while the surface pass asks it about the samples
            try:
                cand = ~mine.update(posed[chunk], world[chunk]).outside(world[chunk])  # the chunk's frames at once
                moved, hit = resolver.frames(torch.from_numpy(world[chunk]), field, cand, mine.outside)
            finally:
                cullers.put(mine)
        world[chunk], inside[chunk] = moved.numpy(), hit.numpy()

    if workers == 1:
        for chunk in chunks:
            correct(chunk)
    else:  # one torch thread a worker: measured faster than two each on two cores (benchmarks/collision.py)
        with torch_threads(1), ThreadPoolExecutor(workers) as pool:
            list(pool.map(correct, chunks))  # list(): an exception in a chunk is raised here
    return world, inside


#: Metres inside the collision body from which :func:`correct_exact_motion` takes a vertex towards the garment skinned
#: to the body, and the depth where it takes it wholly (loosefit's, before SwinGar Eq. 10). Cloth centimetres inside
#: (a dress's bodice left upright in a torso leaning forward, a strap through the neck) is often closer to the far
#: side of a thin part than to where it came in: Eq. 10 sends neighbours out on opposite sides and the surface tears
#: into spikes (the shipped dress on a dribble of the validation subject: 1.8 % of its triangles over 4 times their
#: rest area, a vertex moved 56 cm). Chosen on the validation subject (CMU subject 6) over 2-5, 3-6 and 4-7 cm and
#: 1 or 3 passes of :data:`FALLBACK_SMOOTH`: 4-7 cm with 3 kept the dress's validation RMSE (77.7 -> 77.6 mm
#: VirtualBones, 80.7 -> 80.6 JointNet; 2-5 cm cost 1.4 and 3.0 mm) and lowered or kept the shares of triangles
#: stretched over 4 times or collapsed under 20 % of their rest area for both garments and methods on every
#: validation clip (benchmarks/experiments/skinned_fallback.py, benchmarks/experiments/LOG.md).
SKINNED_FALLBACK = (0.04, 0.07)
#: Passes of one-ring averaging that spread the fallback's weights (:func:`fallback_weights`): the cloth taken over
#: fades into the cloth around it over a few rings instead of stretching across one.
FALLBACK_SMOOTH = 3


def fallback_weights(depth: np.ndarray, resolver: CollisionResolver) -> np.ndarray:
    """``(T, V)`` weights in [0, 1] of the garment skinned to the body, from the vertices' depths inside the body
    ``depth (T, V)`` (metres, negative outside): 0 up to :data:`SKINNED_FALLBACK` ``[0]``, 1 from ``[1]``, linear
    between; then the largest over each vertex's two rings of neighbours (the ``resolver``'s mesh), then averaged over
    its one ring with itself :data:`FALLBACK_SMOOTH` times, so that a piece taken over fades into the cloth around
    it."""
    low, high = SKINNED_FALLBACK
    w = np.clip((np.asarray(depth, np.float64) - low) / (high - low), 0.0, 1.0)
    count = np.diff(resolver.start)
    owner = np.flatnonzero(count)
    if not w.any() or not len(owner):
        return w
    first, nbr = resolver.start[owner], resolver.neighbours
    for _ in range(2):
        grown = w.copy()
        grown[:, owner] = np.maximum(w[:, owner], np.maximum.reduceat(w[:, nbr], first, axis=1))
        w = grown
    for _ in range(FALLBACK_SMOOTH):
        total = w.copy()
        total[:, owner] += np.add.reduceat(w[:, nbr], first, axis=1)
        w = total / (1.0 + count)
    return w


def taken_to_skinned(verts: np.ndarray, depth: np.ndarray, resolver: CollisionResolver,
                     skinned: np.ndarray) -> np.ndarray:
    """``verts (T, V, 3)`` taken towards the garment ``skinned (T, V, 3)`` to the body by :func:`fallback_weights` of
    their depths ``depth (T, V)`` inside it (metres), float32."""
    w = fallback_weights(depth, resolver)[..., None]
    return ((1.0 - w) * verts + w * skinned).astype(np.float32)


def correct_exact_motion(verts: np.ndarray, resolver: CollisionResolver, posed: np.ndarray, faces: np.ndarray,
                         culler: AxisRayCuller | None = None, skinned: np.ndarray | None = None) -> np.ndarray:
    """SwinGar Eq. 10 with the exact field (and the resolver's surface pass) on every frame of an animated garment,
    :data:`FRAME_CHUNK` frames a pass on one thread: each chunk's posed collision surfaces in one
    :class:`~loosefit.geometry.warp_sdf.MotionMeshSDF` (Warp BVHs refitted, not rebuilt),
    :class:`ExactMotionSDF`, :meth:`CollisionResolver.frames`. What :func:`correct_frame` with :class:`ExactSDF`
    (libigl) gives frame by frame, up to float rounding (Warp finds the closest triangle in float32).

    Args:
        verts: ``(T, V, 3)`` world garment vertices, metres.
        resolver: the garment's :class:`CollisionResolver`.
        posed: ``(T, Vb, 3)`` the collision surface of each frame; ``faces (Fb, 3)`` its triangles.
        culler: its :class:`~loosefit.geometry.ray_cull.AxisRayCuller`; None: every vertex reaches the field.
        skinned: ``(T, V, 3)`` the garment skinned to the body (:func:`~loosefit.sim.attach.body_lbs`): first, each
            vertex more than ``SKINNED_FALLBACK[0]`` inside is taken towards it (:func:`fallback_weights`); None:
            no fallback (SwinGar Eq. 10 and the surface pass only).

    Returns:
        ``(T, V, 3)`` float32 corrected vertices.
    """
    out = np.array(verts, np.float32, copy=True)
    T = len(out)
    if resolver.sigma is None and T:  # the first frame's mean edge, as frame by frame
        resolver.sigma = resolver.mean_edge(torch.from_numpy(out[0]))
    field = warp_sdf.MotionMeshSDF(faces, min(FRAME_CHUNK, max(T, 1)))
    sdf = ExactMotionSDF(field)
    for start in range(0, T, FRAME_CHUNK):
        chunk = slice(start, min(start + FRAME_CHUNK, T))
        world = out[chunk]
        field.refit(posed[chunk])
        if culler is None:
            cand, outside = np.ones(world.shape[:2], bool), None
        else:
            cand, outside = ~culler.update(posed[chunk], world).outside(world), culler.outside
        if skinned is not None:
            frame, vertex = np.nonzero(cand)
            depth = np.full(cand.shape, -np.inf)
            depth[frame, vertex] = -field.query(world[frame, vertex], frame)[0]
            world = taken_to_skinned(world, depth, resolver, skinned[chunk])
            if culler is not None:  # the moved vertices asked again (the window still holds: sound anyway)
                cand = ~culler.outside(world)
        out[chunk] = resolver.frames(torch.from_numpy(world), sdf, cand, outside)[0].numpy()
    return out


#: What ``loosefit view`` and ``report --collision`` take: a mode of :func:`handle_motion_collisions` that needs
#: no network, or no handling (``animate`` also takes a body SDF run folder).
POST_PROCESSES = ("exact", "pushout", "none")


def check_post_process(handling: str) -> str:
    """``handling`` if it is one of :data:`POST_PROCESSES`, else an :class:`InputError`."""
    if handling not in POST_PROCESSES:
        raise InputError(f"collision handling must be exact, pushout or none, got {handling!r}")
    return handling


def post_process(verts: np.ndarray, faces: np.ndarray, body, motion, handling: str,
                 rest: np.ndarray | None = None) -> np.ndarray:
    """An animation ``verts (T, V, 3)`` after ``handling`` (:data:`POST_PROCESSES`): as it is for ``"none"``,
    else corrected by :func:`handle_motion_collisions` (``rest``: the garment's rest mesh, for its fallback)."""
    if check_post_process(handling) == "none":
        return verts
    return handle_motion_collisions(verts, faces, body, motion, handling, rest=rest)


#: Metres the exact handling moves its collision surface out along its vertex normals, beyond the posed proxy
#: pushed to enclose the posed full-resolution body (:func:`~loosefit.sim.collider.enclosing_frames`). The
#: 1,229-vertex proxy itself lies up to 13 mm inside the body a user sees (the lower back on a walk), so a vertex
#: put on its surface could stay more than 5 mm inside the body: worst frame 1.45 % of the VirtualBones skirt's
#: vertices on the CMU walk with the proxy moved out 4 mm, 0.94 % on the enclosing surface plus 2 mm
#: (``benchmarks/penetration.py``); 2 mm keeps cloth resting on the body close to it.
PROXY_INFLATE = 0.002


def inflated(verts: np.ndarray, faces: np.ndarray, distance: float) -> np.ndarray:
    """``verts (T, V, 3)`` (or ``(V, 3)``) of a closed mesh moved ``distance`` metres out along each frame's
    vertex normals (angle-weighted), float32."""
    v = np.asarray(verts, np.float64)
    one = v.ndim == 2
    frames = v[None] if one else v
    out = np.empty(frames.shape, np.float32)
    for start in range(0, len(frames), FRAME_CHUNK):  # frames at once, a few MB each
        chunk = frames[start:start + FRAME_CHUNK]
        out[start:start + FRAME_CHUNK] = chunk + distance * angle_weighted_normals(chunk, faces)[1]
    return out[0] if one else out


def handle_motion_collisions(verts: np.ndarray, faces: np.ndarray, body, motion, mode: str = "exact",
                             net: BodySDFNet | None = None, push_distance: float = 0.004,
                             cull: bool = True, margin: float = 0.0, cull_cell=CULL_CELL,
                             inflate: float = PROXY_INFLATE, surface: bool = True,
                             exact_backend: str = "auto", passes: int = SURFACE_PASSES,
                             rest: np.ndarray | None = None) -> np.ndarray:
    """Collision post-process of an animated garment, any method: world ``verts (T, V, 3)`` on ``body`` (an
    Anny body of the right shape) following ``motion`` -> corrected ``(T, V, 3)`` float32.

    ``mode``: ``"neural"`` (SwinGar Eq. 10 with ``net``, in the canonical frame, the code from the motion),
    ``"exact"`` (SwinGar Eq. 10 with the exact distance, Warp's or libigl's (``exact_backend``), to the posed proxy
    made to enclose the body, below) or
    ``"pushout"`` (the fixed-distance baseline). With ``cull`` (the default) SwinGar Eq. 10 evaluates its field only
    at the vertices that the posed proxy's :class:`~loosefit.geometry.ray_cull.AxisRayCuller` cannot prove outside
    (:func:`correct_frame`); the network runs on :data:`FRAME_CHUNK` frames a pass (:func:`correct_motion`); the
    Gaussian width is the mean edge length of the first frame. ``cull_cell``: the cull's bin side, metres (one
    or ``(x, y, z)``).

    ``margin`` (metres, ``"neural"`` only; ours, 0 in the paper): Eq. 10 on the network's surface moved that far
    outwards, ``S - margin``: a vertex the network puts less than ``margin`` outside is corrected too, and moved
    to ``margin + delta_i``. A network that is millimetres off near the surface misses the shallow collisions
    on the wrong side of its zero level; the margin catches them (the cull still skips every vertex it proves
    outside the proxy, so no vertex far from the body moves).

    ``"exact"`` corrects against the posed proxy pushed out to enclose the posed full-resolution body in every
    frame (:func:`~loosefit.sim.collider.enclosing_frames`, over the garment's box), moved ``inflate`` metres
    further out along its vertex normals (:data:`PROXY_INFLATE`).

    ``surface`` (``"neural"`` and ``"exact"``; loosefit's addition beyond SwinGar Eq. 10, on by default): after the
    vertices, the body passing through a triangle or an edge between them is resolved too
    (:class:`CollisionResolver`: the field at every edge midpoint and triangle centroid the cull cannot prove
    outside, the vertices of the deep ones moved until none is inside, :data:`SURFACE_PASSES` passes at most or
    ``passes``); False: the vertices only, as the paper.

    ``rest`` (``"exact"`` only): the garment's rest mesh ``(V, 3)`` on the rest body (a run's template). With it,
    before SwinGar Eq. 10, a vertex more than :data:`SKINNED_FALLBACK` ``[0]`` inside the collision body is taken
    towards the garment skinned to the body (:func:`fallback_weights`): cloth centimetres inside cannot be pushed
    out whole. None: no fallback.

    ``exact_backend`` (``"exact"`` only): ``"auto"`` (Warp when it loads: :func:`correct_exact_motion`, many frames
    a pass; else libigl), ``"warp"`` or ``"igl"`` (libigl's tree rebuilt each frame, :func:`correct_frame` frame by
    frame: the reference; 1.4-1.9 times the CPU time on the shipped skirts, benchmarks/experiments/LOG.md).
    """
    if exact_backend not in ("auto", "warp", "igl"):
        raise InputError(f"exact collision backend must be 'auto', 'warp' or 'igl', got {exact_backend!r}")
    if exact_backend == "warp" and not warp_sdf.available():
        raise InputError("the Warp exact collision handling needs warp (pip install warp-lang)")
    if mode not in ("neural", "exact", "pushout"):
        raise InputError(f"collision mode must be 'neural', 'exact' or 'pushout', got {mode!r}")
    if mode == "neural" and net is None:
        raise InputError("neural collision handling needs a body SDF network")
    if not (np.isfinite(margin) and margin >= 0):
        raise InputError(f"collision margin must be a non-negative number of metres, got {margin!r}")
    if not (np.isfinite(inflate) and inflate >= 0):
        raise InputError(f"proxy inflation must be a non-negative number of metres, got {inflate!r}")
    proxy = body.collision_proxy()
    out = np.array(verts, np.float32, copy=True)
    if mode == "exact":
        posed = enclosing_frames(body, motion, within=out)
        if inflate > 0:
            posed = inflated(posed, proxy.faces, inflate)
    else:
        posed = proxy.pose(motion).verts if cull or mode == "pushout" else None
    culler = AxisRayCuller(posed[0], proxy.faces, cull_cell) if cull and mode != "pushout" else None
    resolver = CollisionResolver(faces, out.shape[1], surface=surface, passes=passes)
    skinned = None
    if rest is not None and mode == "exact":
        rest = np.asarray(rest, np.float32)
        if rest.shape != out.shape[1:]:
            raise InputError(f"the garment's rest mesh must be {out.shape[1:]} like its frames, got {rest.shape}")
        skinned = body_lbs(rest, body, motion)
    if mode == "neural":
        code, rot, origin = motion_sdf_inputs(body, motion, net.num_bones > 0)
        return correct_motion(out, resolver, net.eval(), code, rot, origin, posed, culler, margin)[0]
    if mode == "exact" and exact_backend != "igl" and warp_sdf.available():
        return correct_exact_motion(out, resolver, posed, proxy.faces, culler, skinned)
    meshes = posed_body_sdfs(posed, proxy.faces)
    for t in range(len(out)):
        mesh = next(meshes)  # each frame's tree; the edge map built once
        if mode == "pushout":
            out[t] = push_out(out[t], mesh, push_distance)[0]
        else:
            if skinned is not None:
                out[t] = taken_to_skinned(out[t][None], -mesh.query(out[t])[None], resolver, skinned[t][None])[0]
            out[t] = correct_frame(out[t], resolver, ExactSDF(mesh), None,
                                   culler.update(posed[t], out[t]) if culler else None)[0]
    return out

