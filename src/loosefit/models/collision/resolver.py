"""Moving garment vertices out of the body: SwinGar Eq. 10 and the push-out baseline.

Sign convention: loosefit's (:mod:`loosefit.geometry.signed_distance`): negative inside the body, the gradient
pointing outwards. SwinGar Eq. 7 calls the inside positive, with which SwinGar Eq. 10 would move a vertex further
in; the displacement here is along the outward gradient, as intended there.

- :class:`CollisionResolver` / :func:`resolve_collisions`: SwinGar Eq. 10 for any SDF (the network,
  :class:`ExactSDF` from libigl, or a closed-form one): a vertex with ``S(x_i) < 0`` moves to
  ``x_i + grad S / |grad S| * (|S(x_i)| + delta_i)``, ``delta_i`` the Gaussian-weighted ``|S|`` of its free
  neighbours.
- The surface pass (loosefit's addition beyond SwinGar Eq. 10, which moves vertices only): a limb can pass through
  a triangle or an edge whose vertices are all outside it (a knee through a skirt between its vertices: 59-71 mm
  inside at edge midpoints and centroids on a kick, a run and a lunge). :class:`CollisionResolver` (``surface``,
  on by default) also evaluates the field at every edge's midpoint and triangle's centroid and moves the vertices
  of a sample inside the body out along the field's gradient at it, until no sample is inside or
  :data:`SURFACE_PASSES` passes have run.
- :func:`push_out`: the fixed-distance baseline (TailorNet) the paper compares with.

Applying them to the frames of an animated garment (culling, chunks of frames, threads) is
:mod:`loosefit.models.collision.handling`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import torch

from loosefit.errors import InputError
from loosefit.geometry.laplacian import edges
from loosefit.geometry.signed_distance import BodySDF
from loosefit.models.collision.fast_eval import MotionBodySDF, flushed_denormals, value_and_gradient_fn
from loosefit.models.collision.network import SDFFunction

#: Closest-triangle distance (m) beyond which :class:`ExactSDF` checks a point's side by its winding number.
WINDING_FROM = 0.005
#: Passes of the surface pass at most (each: the samples that can be deep checked, the vertices of the deep ones
#: moved). One pass puts a deep sample on the surface where the field is a distance (the normal line through a
#: point meets the surface at its closest point); more mend what a pass changes next to it: cloth straddling a
#: limb (a triangle on both sides of a thigh) is wrapped around it a ring of triangles a pass. On a skinned 3.9k
#: vertex skirt through a kicking or running leg the deepest edge midpoint or centroid left was 44-49 mm after 4
#: passes, 27 mm after 8, 19-21 mm after 16, for 20 % more field queries than 8 (benchmarks/surface_collision.py).
#: Chosen on the shipped skirts and dresses over clips of the real-capture validation subject: the deepest point
#: left over ten runs and clips was 50.5 mm after 8 passes, 27.7 after 32, 15.8 after 64 and 26.0 after 128 (the
#: cascade does not always settle); the later passes see only the samples next to the last moves, so 64 cost 0-25 %
#: more time than 8 (benchmarks/experiments/LOG.md).
SURFACE_PASSES = 64
#: Metres a surface sample must be inside the field's surface (``S < -SURFACE_TOLERANCE``) to be moved: cloth
#: resting on the body is left alone (the chord of a 2 cm edge on a waist of 15 cm radius sags 0.33 mm inside it),
#: and a sample put on the surface by the previous pass is not moved again for its float rounding. A hundredth
#: of the 59-71 mm a knee went through a skirt between its vertices.
SURFACE_TOLERANCE = 5e-4


class ExactSDF:
    """The body's exact signed distance (libigl, :class:`BodySDF`) as an :data:`SDFFunction`: values from the
    mesh, gradients the unit direction from the closest surface point (outwards), so that
    :func:`resolve_collisions` can use it as the reference for the network.

    Args:
        mesh: a :class:`BodySDF` (the posed body, its tree built once).
    """

    def __init__(self, mesh: BodySDF):
        self.mesh = mesh

    def _query(self, points: torch.Tensor, outside_beyond: np.ndarray | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Signed distances ``(N,)`` and unit outward gradients ``(N, 3)``, as tensors like ``points``.
        ``outside_beyond (N,)``: metres; a point farther than this from the surface is known to be outside (a
        point of the garment near one known to be outside, :meth:`CollisionResolver._surface`), and its side is
        not checked by the winding number."""
        p = points.detach().cpu().double().numpy()
        dist, closest, face = self.mesh.closest(p)
        # A posed body can fold through itself (the hips on a spin): there the closest triangle's side can say
        # outside for a point centimetres inside; the winding number settles it (for points more than
        # WINDING_FROM out: the cases seen were 26-82 mm, and most candidates are cloth resting on the skin).
        far = dist > WINDING_FROM
        if outside_beyond is not None:
            far &= dist <= outside_beyond
        out = np.nonzero(far)[0]
        if len(out):
            dist[out[self.mesh.inside(p[out])]] *= -1.0
        return _as_field(points, p, dist, closest, self.mesh.face_normals[face])

    def __call__(self, points: torch.Tensor) -> torch.Tensor:
        value, direction = self._query(points)
        # the value with the exact gradient attached: d/dx (value + n . (x - x0)) = n
        return value + (direction * (points - points.detach())).sum(-1)

    def value_and_gradient_fn(self, points: torch.Tensor, outside_beyond: np.ndarray | None = None):
        """Values ``(N,)`` and ``rows -> gradients (M, 3)`` from one query (see :func:`value_and_gradient_fn`;
        ``outside_beyond``: see :meth:`_query`)."""
        value, direction = self._query(points, outside_beyond)
        return value, lambda rows: direction[rows]


def _as_field(points: torch.Tensor, p: np.ndarray, dist: np.ndarray, closest: np.ndarray, face_normal: np.ndarray):
    """Signed distances ``dist (N,)`` and unit outward gradients ``(N, 3)`` (from the closest points ``(N, 3)``,
    the face normal ``(N, 3)`` on the surface) at ``p (N, 3)``, as tensors like ``points``."""
    away = p - closest
    norm = np.linalg.norm(away, axis=1, keepdims=True)
    direction = np.where(norm > 1e-9, away / np.maximum(norm, 1e-12) * np.sign(dist)[:, None], face_normal)
    as_points = dict(dtype=points.dtype, device=points.device)
    return torch.as_tensor(dist, **as_points), torch.as_tensor(direction, **as_points)


class ExactMotionSDF(ExactSDF):
    """:class:`ExactSDF` of the frames of a motion at once, for :meth:`CollisionResolver.frames`: each point is
    given with its frame's index and the field is a
    :class:`~loosefit.geometry.warp_sdf.MotionMeshSDF` (Warp; libigl's distances to about 1e-7 m, the same sign
    rule).

    Args:
        field: a :class:`~loosefit.geometry.warp_sdf.MotionMeshSDF` refitted to the frames.
    """

    def __init__(self, field):
        self.field = field

    @property
    def num_frames(self) -> int:
        return self.field.num_frames

    def _query(self, points: torch.Tensor, frame: torch.Tensor,
               outside_beyond: np.ndarray | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`ExactSDF._query` for ``points (N, 3)`` of frames ``frame (N,)``."""
        p = points.detach().cpu().double().numpy()
        fr = frame.cpu().numpy()
        dist, closest, face = self.field.query(p, fr, WINDING_FROM, outside_beyond)
        # rounded as BodySDF.closest rounds libigl's: the same moves as ExactSDF's, not just float noise apart
        dist, closest = dist.astype(np.float32), closest.astype(np.float32)
        normals = self.field.face_normals
        return _as_field(points, p, dist, closest, normals.reshape(-1, 3)[fr * normals.shape[1] + face])

    def __call__(self, points: torch.Tensor, frame: torch.Tensor) -> torch.Tensor:
        value, direction = self._query(points, frame)
        return value + (direction * (points - points.detach())).sum(-1)

    def value_and_gradient_fn(self, points: torch.Tensor, frame: torch.Tensor,
                              outside_beyond: np.ndarray | None = None):
        """Values ``(N,)`` and ``rows -> gradients (M, 3)`` at ``points (N, 3)`` of frames ``frame (N,)``."""
        value, direction = self._query(points, frame, outside_beyond)
        return value, lambda rows: direction[rows]


def vertex_neighbours(faces: np.ndarray, num_verts: int) -> tuple[np.ndarray, np.ndarray]:
    """Both directions of every mesh edge: ``src, dst (2E,)`` int64."""
    e = edges(np.asarray(faces, np.int64))
    return np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]])


def surface_sample_weights(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The points between the vertices that the surface pass checks: every edge's midpoint, then every triangle's
    centroid, in the order of :func:`loosefit.metrics.collision.surface_samples` (the measure they are checked
    for). Returns their vertices ``(S, 3)`` int64 and barycentric weights ``(S, 3)`` float64, ``S = E + F`` (an
    edge's third vertex is its first, with weight 0)."""
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    e = edges(f)
    index = np.concatenate([np.concatenate([e, e[:, :1]], 1), f])
    weight = np.concatenate([np.tile([0.5, 0.5, 0.0], (len(e), 1)), np.full((len(f), 3), 1.0 / 3.0)])
    return index, weight


def _bool_mask(mask, shape: tuple) -> np.ndarray:
    """``mask`` (NumPy or torch) as a NumPy bool array of ``shape``, or a clear error."""
    mask = mask.cpu().numpy() if isinstance(mask, torch.Tensor) else np.asarray(mask)
    if mask.shape != shape or mask.dtype != bool:
        raise InputError(f"candidates must be a {shape} bool mask, got {mask.dtype} {mask.shape}")
    return mask


class CollisionResolver:
    """SwinGar Eq. 10 on one garment mesh: its neighbour lists are built once, then each call moves the
    vertices a field says are inside out of the body.

    For a vertex with ``S(x_i) < 0``: ``x_i + grad S / |grad S| * (|S(x_i)| + delta_i)``, where ``delta_i`` is the
    Gaussian-weighted average of ``|S|`` over its mesh neighbours that are not inside (weights
    ``exp(-d^2 / (2 sigma^2))`` of their distances, normalised to mean 1; 0 without such a neighbour).
    One step leaves a vertex inside only where the field's gradient is not a unit vector: on the medial
    axis of a non-smooth field, or where a learned field is not yet a distance.

    The field is evaluated where it is needed, not everywhere: its value at the ``candidates`` (every vertex by
    default), its value at the other neighbours of the vertices found inside (their ``|S|`` enters
    ``delta_i``), and its gradient at the inside vertices only. A vertex left out of ``candidates`` must be known
    to be outside (:class:`~loosefit.geometry.ray_cull.AxisRayCuller` proves it); it is never moved and counts as
    a free neighbour. With every vertex a candidate the result is that of evaluating the field everywhere.

    The surface pass (``surface``; loosefit's addition beyond SwinGar Eq. 10, which resolves vertices only) then
    looks between the vertices, at the samples of :func:`surface_sample_weights` (edge midpoints and triangle
    centroids, ``p = sum_j w_j x_j``). A sample is given to the field unless the ``outside`` test proves it outside
    or one of its vertices is known to be farther out than its distance to ``p`` (a distance field changes by at
    most the distance: ``S(p) >= S(x_j) - |p - x_j|``). For each with ``S(p) < -SURFACE_TOLERANCE`` every vertex
    ``j`` of it is asked to move by ``d n w_j / sum_k w_k^2`` (``d = |S(p)|``, ``n`` the unit gradient at ``p``):
    together these put ``p`` itself on the surface. A vertex asked by several samples takes the largest ask (the
    sum would move it once per deep sample; the mean, too little for the deepest). The next pass checks the
    samples touching a moved vertex, the vertex itself among them (moved along another point's normal, it can
    end in another part of the body), up to ``passes`` passes; when they run out, SwinGar Eq. 10 checks the last
    pass's moves. A triangle or edge with no sample inside is not moved; one next to it can be, in a later pass,
    when the move of a shared vertex pulled it into the body.

    Args:
        faces: ``(F, 3)`` triangles (the neighbourhoods, and the surface samples).
        num_verts: ``V``.
        sigma: Gaussian width, metres; None: the mean edge length of the first mesh given to :meth:`__call__`.
        surface: run the surface pass after SwinGar Eq. 10 (False: the paper's vertex-only handling).
        passes: surface passes at most (:data:`SURFACE_PASSES`); the surface samples ``S = E + F + V`` (the
            vertices last) are built once, like the neighbour lists.
    """

    def __init__(self, faces: np.ndarray, num_verts: int, sigma: float | None = None, surface: bool = True,
                 passes: int = SURFACE_PASSES):
        src, dst = vertex_neighbours(faces, num_verts)
        self.src, self.dst = src, dst
        order = np.argsort(src, kind="stable")
        self.neighbours = dst[order]  # CSR: the neighbours of i are neighbours[start[i]:start[i + 1]]
        self.start = np.concatenate([[0], np.cumsum(np.bincount(src, minlength=num_verts))])
        self.num_verts = num_verts
        self.sigma = sigma
        if passes < 0:
            raise InputError(f"surface passes must be >= 0, got {passes}")
        self.surface, self.passes = bool(surface), int(passes)
        index, weight = surface_sample_weights(faces)
        self.num_surface = len(index)  # then each vertex as a sample of its own (checked again once moved)
        own = np.arange(num_verts)
        self.sample_index = np.concatenate([index, np.stack([own, own, own], 1)])
        self.sample_weight = np.concatenate([weight, np.tile([1.0, 0.0, 0.0], (num_verts, 1))])
        # what each vertex of a sample moves per metre of the sample's depth: w_j / sum_k w_k^2
        self.sample_push = self.sample_weight / (self.sample_weight**2).sum(1, keepdims=True)
        rows = np.repeat(np.arange(len(self.sample_index)), 3)  # (S, V): every sample of a frame in one product
        self.sample_matrix = sp.csr_matrix((self.sample_weight.ravel(), (rows, self.sample_index.ravel())),
                                           shape=(len(self.sample_index), num_verts))
        # CSR: the samples that vertex i is part of are sample_of[sample_start[i]:sample_start[i + 1]]
        sample, corner = np.nonzero(self.sample_weight > 0)
        owner = self.sample_index[sample, corner]
        self.sample_of = sample[np.argsort(owner, kind="stable")]
        self.sample_start = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=num_verts))])

    def mean_edge(self, verts: torch.Tensor) -> float:
        """Mean edge length of ``verts (V, 3)``, metres (1 for a mesh without edges)."""
        if len(self.src) == 0:
            return 1.0
        src, dst = (torch.from_numpy(a).to(verts.device) for a in (self.src, self.dst))
        return float((verts[src] - verts[dst]).norm(dim=-1).mean())  # each edge twice: the same mean

    def __call__(self, verts: torch.Tensor, sdf: SDFFunction, candidates=None, outside=None):
        """Move the inside vertices of ``verts (V, 3)`` (metres, in the SDF's frame) out, then (``surface``) the
        triangles and edges the body passes through between them.

        Args:
            verts: ``(V, 3)`` garment vertices.
            sdf: an :data:`SDFFunction` (a :meth:`BodySDFNet.bind`, :class:`ExactSDF`, ...).
            candidates: ``(V,)`` bool (NumPy or torch), the vertices that may be inside; None: all.
            outside: ``points (N, 3) -> (N,)`` bool, True for points certainly outside (an
                :meth:`AxisRayCuller.outside` updated to this frame): the surface samples it proves outside are not
                given to the field; None: every sample is.

        Returns:
            ``(V, 3)`` corrected vertices and the ``(V,)`` bool mask of the vertices moved (found inside, or moved
            by the surface pass).
        """
        V = self.num_verts
        if verts.ndim != 2 or verts.shape != (V, 3):
            raise InputError(f"resolve_collisions takes one garment ({V}, 3), got {tuple(verts.shape)}")
        cand = np.arange(V) if candidates is None else np.flatnonzero(_bool_mask(candidates, (V,)))
        moved, inside = self._resolve(verts, sdf, cand, outside=outside)
        return moved, torch.from_numpy(inside).to(verts.device)

    def frames(self, verts: torch.Tensor, sdf: "MotionBodySDF", candidates,
               outside=None) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`__call__` on ``T`` frames of the garment at once: ``verts (T, V, 3)`` world metres, ``sdf`` the
        :class:`MotionBodySDF` of those frames, ``candidates (T, V)`` bool (NumPy or torch), ``outside``: ``points
        (T, N, 3) -> (T, N)`` bool (an :class:`AxisRayCuller` updated to these frames) or None. Returns
        ``(T, V, 3)`` and ``(T, V)`` bool, what :meth:`__call__` gives frame by frame (up to float rounding)."""
        V = self.num_verts
        if verts.ndim != 3 or verts.shape[1:] != (V, 3):
            raise InputError(f"resolving frames takes a garment (T, {V}, 3), got {tuple(verts.shape)}")
        T = len(verts)
        cand = np.flatnonzero(_bool_mask(candidates, (T, V)))
        if getattr(sdf, "num_frames", None) != T:
            raise InputError(f"resolving {T} frames needs a MotionBodySDF of {T} frames")
        moved, inside = self._resolve(verts.reshape(T * V, 3), sdf, cand, frames=True, outside=outside)
        return moved.reshape(T, V, 3), torch.from_numpy(inside.reshape(T, V)).to(verts.device)

    def _resolve(self, verts: torch.Tensor, sdf, cand: np.ndarray, frames: bool = False, outside=None):
        """The moved copy of ``verts`` and the NumPy mask of the vertices moved, evaluating ``sdf`` at the
        flat indices ``cand`` (and where ``delta_i`` needs it), then at the surface samples (:meth:`_surface`).
        The field runs in torch on the vertices' device; the bookkeeping of a few hundred vertices runs in NumPy
        (cheaper per call). With ``frames``, ``verts`` is ``(T V, 3)``, flat index ``t V + i`` is vertex ``i`` of
        frame ``t``, and ``sdf`` (a :class:`MotionBodySDF`) takes each point's frame. The Gaussian width, if not
        set, is the mean edge of the first frame."""
        if self.sigma is None:
            self.sigma = self.mean_edge(verts[:self.num_verts])
        out = verts.detach().clone()
        inside = np.zeros(len(out), bool)
        with flushed_denormals():
            value = self._move_out(out, sdf, cand, inside, frames)
            if self.surface and self.passes and self.num_surface:
                known = np.where(np.isnan(value), 0.0, value)  # not a candidate: proved outside
                known[inside] = -np.inf  # moved: unknown
                self._surface(out, sdf, inside, known, frames, outside)
        return out, inside

    def _corners(self, frame: np.ndarray, sample: np.ndarray) -> np.ndarray:
        """``(N, 3)`` flat vertex indices ``t V + i`` of the corners of samples ``sample (N,)`` of frames
        ``frame (N,)``."""
        return (frame * self.num_verts)[:, None] + self.sample_index[sample]

    def _surface(self, out: torch.Tensor, sdf, moved: np.ndarray, known: np.ndarray, frames: bool,
                 outside) -> None:
        """The surface pass (loosefit's, beyond SwinGar Eq. 10; see the class), in place on ``out (T V, 3)``,
        marking the vertices it moves in ``moved (T V,)``. ``known (T V,)``: a lower bound of the field at each
        vertex (its value where evaluated, 0 where the cull proved it outside, -inf unknown). Flat sample index
        ``t S + k`` is sample ``k`` of frame ``t``; samples ``E + F`` on are the vertices themselves."""
        dev = out.device
        V, S = self.num_verts, len(self.sample_index)
        T = len(out) // V
        dtype = torch.empty(0, dtype=out.dtype).numpy().dtype  # the vertices' (float32 over a motion)
        cand = (np.arange(T)[:, None] * S + np.arange(self.num_surface)).reshape(-1)  # every edge and triangle
        last = None
        for _ in range(self.passes):
            x = out.cpu().numpy().reshape(T * V, 3)
            sample, frame = cand % S, cand // S
            if last is None:  # every sample: one sparse product a frame
                xt = x.reshape(T, V, 3).transpose(1, 0, 2).reshape(V, T * 3)
                points = (self.sample_matrix @ xt).reshape(-1, T, 3).transpose(1, 0, 2)[:, :self.num_surface]
                points = points.reshape(-1, 3).astype(dtype)
            else:
                corner = self._corners(frame, sample)
                points = np.einsum("nk,nkd->nd", self.sample_weight[sample], x[corner]).astype(dtype)
            if outside is not None:
                kept = ~self._culled(points, frame, T if frames else None, outside, every=last is None)
                cand, sample, frame, points = cand[kept], sample[kept], frame[kept], points[kept]
            corner, weight = self._corners(frame, sample), self.sample_weight[sample]  # of the samples the cull left
            # a field that is a distance changes by at most |p - x_j| from a vertex to a sample: a vertex known to
            # be that far out proves the sample is not deep, and is not asked about it (exact for the exact field;
            # the network is a distance as far as its Eikonal term made it one)
            reach = np.linalg.norm(points[:, None].astype(np.float64) - x[corner], axis=-1)
            bound = np.where(weight > 0, known[corner] - reach, -np.inf).max(1)
            keep = bound < -SURFACE_TOLERANCE
            cand, sample, frame, bound, points = cand[keep], sample[keep], frame[keep], bound[keep], points[keep]
            if len(cand) == 0:
                break
            at = (torch.from_numpy(points).to(dev),)
            if frames:
                at += (torch.from_numpy(frame).to(dev),)
            if isinstance(sdf, ExactSDF):  # farther from the surface than the bound says, a sample is outside
                value, gradient = sdf.value_and_gradient_fn(*at, outside_beyond=-bound)
            else:
                value, gradient = value_and_gradient_fn(sdf, *at)
            value = value.detach().cpu().numpy().astype(np.float64)
            own = sample >= self.num_surface  # the vertices' own samples: their value now
            known[frame[own] * V + sample[own] - self.num_surface] = value[own]
            deep = np.flatnonzero(value < -SURFACE_TOLERANCE)
            if len(deep) == 0:
                last = None
                break
            g = gradient(torch.from_numpy(deep).to(dev)).detach().cpu().numpy().astype(np.float64)
            normal = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
            sample, frame = sample[deep], frame[deep]
            # each vertex of a deep sample is asked to move by d w_j / sum w^2 along the sample's normal
            ask = -value[deep][:, None] * self.sample_push[sample]  # (K, 3)
            vertex = frame[:, None] * V + self.sample_index[sample]  # (K, 3) flat vertices
            row = np.broadcast_to(np.arange(len(deep))[:, None], ask.shape)
            real = ask > 0  # an edge's padding corner asks nothing
            ask, vertex, row = ask[real], vertex[real], row[real]
            # the largest ask of each vertex: sorted by vertex, then ask; the last of each vertex's run
            order = np.lexsort((ask, vertex))
            pick = order[np.r_[vertex[order][1:] != vertex[order][:-1], True]]
            last = vertex[pick]  # sorted, unique
            shift = ask[pick, None] * normal[row[pick]]
            if dev.type == "cpu":  # in place through NumPy (the rows are unique): torch's indexed update cost 5x
                view = out.numpy()  # shares the tensor's memory
                view[last] += shift.astype(view.dtype)
            else:
                rows = torch.from_numpy(last).to(dev)
                out[rows] = out[rows] + torch.from_numpy(shift).to(out)
            moved[last] = True
            known[last] = -np.inf
            # the samples touching a moved vertex are the ones that can have changed, the vertex's own among them
            # (moved along another point's normal, it can end in another part of the body)
            local, frame = last % V, last // V
            count = self.sample_start[local + 1] - self.sample_start[local]
            total = np.cumsum(count)
            touched = self.sample_of[np.repeat(self.sample_start[local] - total + count, count) + np.arange(total[-1])]
            cand = np.unique(touched + np.repeat(frame * S, count))
        if last is not None:  # the passes ran out: the last moves are not checked, unless by SwinGar Eq. 10
            self._move_out(out, sdf, last, np.zeros(len(out), bool), frames)

    @staticmethod
    def _culled(points: np.ndarray, frame: np.ndarray, T: int | None, outside, every: bool) -> np.ndarray:
        """``(N,)`` bool: the cull proves ``points (N, 3)`` (of frames ``frame (N,)``, sorted) outside. ``T``: the
        frames of a frames' cull (points ``(T, N, 3)``, one frame included), None for one frame's (``(N, 3)``).
        ``every``: the points are every sample of every frame, in order; otherwise a frames' cull is given each
        frame's points padded to the same count with a point far outside."""
        if T is None:
            return np.asarray(outside(points))
        if every:
            return np.asarray(outside(points.reshape(T, -1, 3))).reshape(-1)
        count = np.bincount(frame, minlength=T)
        slot = np.arange(len(frame)) - np.repeat(np.cumsum(count) - count, count)
        padded = np.full((T, max(int(count.max()), 1), 3), 1e4, points.dtype)
        padded[frame, slot] = points
        return np.asarray(outside(padded))[frame, slot]

    def _move_out(self, out: torch.Tensor, sdf, cand: np.ndarray, inside: np.ndarray, frames: bool) -> np.ndarray:
        """SwinGar Eq. 10, in place on ``out``, filling ``inside``; returns the field's values ``(T V,)`` where it
        was evaluated (before the moves; NaN elsewhere)."""
        dev = out.device
        V = self.num_verts
        value = np.full(len(out), np.nan)
        if len(cand) == 0:
            return value

        def at(index: np.ndarray) -> tuple:  # the field's arguments for these flat indices
            rows = torch.from_numpy(index).to(dev)
            return (out[rows], rows // V) if frames else (out[rows],)

        x = out.cpu().numpy()
        s_cand, gradient = value_and_gradient_fn(sdf, *at(cand))
        s_cand = s_cand.detach().cpu().numpy().astype(np.float64)
        hit = s_cand < 0
        ins = cand[hit]
        inside[ins] = True
        value[cand] = s_cand
        if len(ins) == 0:
            return value
        g = gradient(torch.from_numpy(np.flatnonzero(hit)).to(dev)).detach().cpu().numpy().astype(np.float64)
        # the neighbours of the inside vertices, flat: neighbour nbr[k] belongs to inside vertex ins[rows[k]]
        vertex = ins % V
        count = self.start[vertex + 1] - self.start[vertex]
        total = np.cumsum(count)
        nbr = self.neighbours[np.repeat(self.start[vertex] - total + count, count) + np.arange(total[-1])]
        nbr = nbr + np.repeat(ins - vertex, count)  # the same frame's
        rows = np.repeat(np.arange(len(ins)), count)
        free = ~inside[nbr]
        need = np.zeros(len(x), bool)
        need[nbr[free]] = True
        need[cand] = False
        missing = np.flatnonzero(need)  # free neighbours not evaluated yet: their |S| enters delta
        if len(missing):
            with torch.no_grad():
                value[missing] = sdf(*at(missing)).cpu().numpy()
        x_in = x[ins].astype(np.float64)
        diff = x_in[rows] - x[nbr]
        d2 = np.einsum("ij,ij->i", diff, diff)
        w = np.exp(-d2 / (2 * self.sigma**2)) * free
        wsum = np.bincount(rows, w, len(ins))
        weighted = np.bincount(rows, w * np.abs(np.where(free, value[nbr], 0.0)), len(ins))
        delta = np.divide(weighted, wsum, out=np.zeros(len(ins)), where=wsum > 0)
        direction = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
        moved = x_in + direction * (np.abs(s_cand[hit]) + delta)[:, None]  # SwinGar Eq. 10
        out[torch.from_numpy(ins).to(dev)] = torch.from_numpy(moved).to(out)
        return value


def resolve_collisions(verts: torch.Tensor, faces: np.ndarray, sdf: SDFFunction, sigma: float | None = None,
                       candidates=None, surface: bool = True):
    """Move every vertex inside the body out of it (SwinGar Eq. 10), then (``surface``, loosefit's addition) the
    triangles and edges the body passes through between vertices: one call of a :class:`CollisionResolver`.

    Args:
        verts: ``(V, 3)`` garment vertices, metres, in the SDF's frame.
        faces: ``(F, 3)`` triangles (the neighbourhoods).
        sdf: an :data:`SDFFunction` (a :meth:`BodySDFNet.bind`, :class:`ExactSDF`, a closed-form one).
        sigma: Gaussian width, metres; None: the mean edge length.
        candidates: ``(V,)`` bool, the vertices that may be inside (the others are known outside); None: all.
        surface: the surface pass (False: SwinGar Eq. 10 on the vertices only, as the paper).

    Returns:
        ``(V, 3)`` corrected vertices and the ``(V,)`` bool mask of the vertices moved.
    """
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise InputError(f"resolve_collisions takes one garment (V, 3), got {tuple(verts.shape)}")
    return CollisionResolver(faces, len(verts), sigma, surface)(verts, sdf, candidates)


def push_out(verts: np.ndarray, body: BodySDF, distance: float = 0.004) -> tuple[np.ndarray, np.ndarray]:
    """The baseline (TailorNet): each vertex inside the body moves to its closest surface point plus
    ``distance`` along the outward direction, whatever its neighbours do. Returns vertices and the mask."""
    v = np.asarray(verts, np.float64)
    dist, closest, face = body.closest(v)
    inside = dist < 0
    away = closest - v
    norm = np.linalg.norm(away, axis=1, keepdims=True)
    direction = np.where(norm > 1e-9, away / np.maximum(norm, 1e-12), body.face_normals[face])
    out = v.copy()
    out[inside] = closest[inside] + distance * direction[inside]
    return out.astype(np.float32), inside
