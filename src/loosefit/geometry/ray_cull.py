"""Which points are certainly outside a closed triangle mesh, by a test cheap enough to run before a costly
signed distance (SwinGar's neural body SDF) so that it is evaluated only where a point may be inside.

A point is certified outside when one of the six axis-aligned rays from it (``+x, -x, +y, -y, +z, -z``)
meets no triangle that faces back along the ray: the ``+a`` ray no triangle whose outward normal has an ``a``
component ``>= 0``, the ``-a`` ray none with one ``<= 0``. Walking in from infinity (winding number 0) along
the ``+a`` ray, crossing a triangle that faces ``+a`` enters the solid (+1), one that faces ``-a`` leaves it
(-1); if the ray crosses only the latter, the point's winding number is minus their count, ``<= 0``: it is not
inside (inside is a winding number ``>= 1``; a negative one needs a mesh turned inside out). For a closed,
consistently oriented mesh that does not cross itself this is also the sign of
:class:`~loosefit.geometry.signed_distance.BodySDF` (libigl's pseudonormal test). A skinned body can cross
itself in some poses; there the two signs can disagree, and the cull follows the winding number: in 6.5M
tests of random points on, near and inside the Anny proxy (two shapes, walk, spin and mix, every seventh
frame, three bin sizes, float32 and float64), 48 (three frames) were of points inside by the pseudonormal sign
(7-35 mm deep) with winding number 0 and a free ray (measured when every triangle stopped every ray); no
certified point had a positive winding number. The test never certifies a point that is inside; it may fail
to certify one that is outside (a point in a pocket such as between an arm and the torso, or close to the
surface), which then goes to the exact test. The orientation (outward or inward normals) is read from the
sign of the mesh's volume.

The rays are tested against bounds binned on a grid: for the ray along axis ``a``, the plane of the two other
axes is cut into bins of sides ``cell`` (per axis); each bin keeps an upper bound ``hi`` of the ``a`` coordinate
of every part of a triangle facing ``+a`` that lies over it (a lower bound ``lo`` of those facing ``-a``). A
triangle the ``+a`` ray from ``p`` meets has a point with the two other coordinates of ``p`` (so over ``p``'s
bin) and an ``a`` coordinate ``>= p_a``: hence ``p_a > hi`` proves the ray free of the triangles that count
(``p_a < lo`` for ``-a``). Leaving the triangles facing away out halves the writes and tightens the bounds: a
back's box no longer hides the front. A point outside the mesh's own box is outside. Per triangle and bin
overlapped by the triangle's box, the bound is the smaller of

- the box's largest ``a`` (smallest for ``lo``), and
- the largest ``a`` of the triangle's plane over the bin's rectangle, which a linear function reaches at a
  corner (smallest for ``lo``); only for planes with ``|da/db| + |da/dc| <= STEEP``, computed in float64.
  It makes the bound tight near a surface facing the ray: a vertex 1-2 cm off the body is certified, where
  boxes of 3-5 cm triangles are not.

The query window (:meth:`AxisRayCuller.update`'s ``within``): when the points to be asked about are known, only
the bins of their box are filled; a triangle whose box reaches none costs its box alone. Later points in a bin
outside the window are left candidates, so the answers stay sound for any point.

Rounding: points and vertices are used in float32. The boxes are widened by ``eps``, four float32 steps at the
mesh's largest coordinate (more than rounding a float64 vertex or point to float32 moves it); the bins'
rectangles by ``eps`` and a millionth of a cell; the plane bound by ``eps (2 + |da/db| + |da/dc|)`` (the plane
of the rounded vertices against the true one, the float64 sums and the final float32 rounding) plus 1e-9 m.
Bin indices come from one monotone formula, ``floor((x - low) * (1 / cell))`` per axis, in float32, for points
and boxes alike, so rounding never drops a triangle from a bin its point's coordinates fall in. A triangle
counts as facing a direction unless its normal's component is clearly the other way
(:data:`FACING_TOLERANCE`).

Two implementations give the same maps: Warp kernels (compiled once and cached on disk; over a motion, one
launch of each for all the frames of an update, about 0.4-0.5 ms a frame for the 2,454 triangles of the Anny
proxy at 2 cm with a garment's window and 0.1 ms for its 10k points, on this project's CPUs) and NumPy (the
reference, used when Warp cannot load).
"""

from __future__ import annotations

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.extras import warp_kernels

#: The two plane axes of each ray axis.
_PLANE = ((1, 2), (0, 2), (0, 1))
#: A triangle steeper than this along a ray axis (``|da/db| + |da/dc|`` of its plane) bounds a bin by its box
#: alone: the plane would hardly be tighter, and its rounding margin grows with the slope.
STEEP = 20.0
#: A triangle is taken to face a ray's direction unless its normal's component along it is clearly the other way:
#: below ``-FACING_TOLERANCE`` times the sum of the two products it is the difference of (far above the float64
#: rounding of that difference).
FACING_TOLERANCE = 1e-9


class AxisRayCuller:
    """Certify points outside a closed mesh by the six axis rays (see the module docstring).

    Build it once for a mesh's faces and call :meth:`update` with each posed frame's vertices (the buffers are
    reused); :meth:`outside` then answers for that frame. Both also take many frames at once (``(T, V, 3)``
    vertices, then ``(T, N, 3)`` points, frame ``t``'s points against frame ``t``'s mesh): the same answers,
    with the kernels launched once for all of them.

    Args:
        verts: ``(V, 3)`` mesh vertices, metres (the first posed frame).
        faces: ``(F, 3)`` int triangles of a closed mesh.
        cell: side of the bins, metres, one for every axis or ``(x, y, z)`` (smaller: tighter near the surface,
            more bins per triangle).
        backend: ``"auto"`` (Warp when it loads, else NumPy), ``"warp"`` or ``"numpy"``.
    """

    def __init__(self, verts: np.ndarray, faces: np.ndarray, cell=0.02, backend: str = "auto"):
        f = np.asarray(faces)
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or not np.issubdtype(f.dtype, np.integer):
            raise InputError(f"AxisRayCuller needs integer faces (F, 3), got {f.dtype} {f.shape}")
        cells = np.broadcast_to(np.asarray(cell, np.float64), (3,))
        if not (cells > 0).all():
            raise InputError(f"cull cell must be positive metres, got {cell}")
        if backend not in ("auto", "warp", "numpy"):
            raise InputError(f"cull backend must be 'auto', 'warp' or 'numpy', got {backend!r}")
        kernels = None if backend == "numpy" else warp_kernels("loosefit.geometry._ray_cull_warp", "rasterize", "query")
        if backend == "warp" and kernels is None:
            raise InputError("the Warp cull backend needs warp (pip install warp-lang)")
        self.backend = "numpy" if kernels is None else "warp"
        self.cell = cells.copy()
        self.faces = np.ascontiguousarray(f, np.int32)
        self.num_verts = int(self.faces.max()) + 1
        self.inv = np.float32(1.0) / cells.astype(np.float32)
        self.orient = None  # +1: outward normals (faces counter-clockwise seen from outside); set by update
        if kernels is not None:
            self._wp, self._rasterize, self._query = kernels
            self._faces = self._wp.array(self.faces, dtype=self._wp.vec3i, device="cpu")
            self._maps = None  # (hi, lo) Warp arrays, grown as needed
        self.update(verts)

    def twin(self) -> "AxisRayCuller":
        """Another culler of the same mesh, bins and backend, with buffers of its own (one per thread), at the
        pose of this one's first frame."""
        return AxisRayCuller(self._first, self.faces, self.cell, self.backend)

    def update(self, verts: np.ndarray, within: np.ndarray | None = None) -> "AxisRayCuller":
        """Rebuild the maps for the mesh posed at ``verts (V, 3)``, or at each of ``T`` frames ``(T, V, 3)``
        (metres); returns ``self``.

        ``within``: the points that will be asked about, ``(N, 3)`` or ``(T, N, 3)`` like ``verts``: the maps then
        cover only the bins of their box (the query window), and the triangles that reach no such bin cost
        nothing (a skirt never asks about the head). A later point in a bin outside the window is left a
        candidate: the answers stay sound for any point, and certify the most for these."""
        v = np.asarray(verts)
        if v.ndim not in (2, 3) or v.shape[-1] != 3 or v.shape[-2] < self.num_verts or (v.ndim == 3 and not len(v)):
            raise InputError(f"AxisRayCuller needs verts (V >= {self.num_verts}, 3) or (T, V, 3), got {v.shape}")
        self._frames = v.ndim == 3
        v32 = np.ascontiguousarray(v.reshape(-1, *v.shape[-2:]), np.float32)  # (T, V, 3)
        self._first = v32[0]
        vmin, vmax = (x.numpy() for x in torch.aminmax(torch.from_numpy(v32), dim=1))
        if not (np.isfinite(vmin).all() and np.isfinite(vmax).all()):
            raise InputError("AxisRayCuller: the mesh has NaN or infinite vertices")
        if self.orient is None:
            tri = self._first.astype(np.float64)[self.faces]
            volume = float(np.einsum("fi,fi->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))) / 6.0
            if volume == 0.0:
                raise InputError("AxisRayCuller needs a closed mesh around a volume (its signed volume is 0)")
            self.orient = 1.0 if volume > 0 else -1.0
        # widening: 4 float32 steps at the largest coordinate (rounding a vertex or a point moves it by half a step)
        largest = np.maximum(np.maximum(np.abs(vmin).max(1), np.abs(vmax).max(1)), np.float32(1.0))
        self.eps = (np.float32(4.0) * np.spacing(largest)).astype(np.float32)  # (T,)
        self.low, self.high = vmin - self.eps[:, None], vmax + self.eps[:, None]  # each frame's (widened) box
        self.bins = np.floor((self.high - self.low) * self.inv).astype(np.int64) + 1  # (T, 3)
        sizes = np.stack([self.bins[:, b] * self.bins[:, c] for b, c in _PLANE], 1)  # (T, 3)
        self._base = (np.cumsum(sizes) - sizes.ravel()).reshape(sizes.shape)  # where each frame's map starts
        n = int(sizes.sum())
        self.window = self._window(within, len(v32))
        if self.backend == "warp":
            wp = self._wp
            if self._maps is None or self._maps[0].shape[0] < n:
                self._maps = tuple(wp.empty(max(n, 2 * (0 if self._maps is None else self._maps[0].shape[0])),
                                            dtype=float, device="cpu") for _ in range(2))
            hi, lo = self._maps
            self.hi, self.lo = hi.numpy()[:n], lo.numpy()[:n]  # views of the Warp buffers
            self.hi.fill(-np.inf)
            self.lo.fill(np.inf)
            self._frame_args = [wp.array(a, dtype=d, device="cpu") for a, d in
                                ((self.low, wp.vec3), (self.high, wp.vec3), (self.bins.astype(np.int32), wp.vec3i),
                                 (self._base.astype(np.int32), wp.vec3i), (self.window[0].astype(np.int32), wp.vec3i),
                                 (self.window[1].astype(np.int32), wp.vec3i))]
            low, high, bins, base, win0, win1 = self._frame_args
            wp.launch(self._rasterize, dim=(len(v32), len(self.faces)), device="cpu",
                      inputs=[wp.array(v32, dtype=wp.vec3, device="cpu", copy=False), self._faces,
                              wp.array(self.eps, dtype=float, device="cpu", copy=False), low, wp.vec3(*self.inv),
                              bins, base, win0, win1, self.orient, hi, lo])
            return self
        self.hi = np.full(n, -np.inf, np.float32)
        self.lo = np.full(n, np.inf, np.float32)
        for t in range(len(v32)):
            self._rasterize_numpy(v32[t], t)
        return self

    def _window(self, within, T: int) -> tuple[np.ndarray, np.ndarray]:
        """The query window: the first and last bin ``(T, 3)`` of ``within``'s box per frame (all bins: None)."""
        first, last = np.zeros((T, 3), np.int64), self.bins - 1
        if within is None:
            return first, last
        p = np.asarray(within)
        if p.shape[-1:] != (3,) or p.ndim != (3 if self._frames else 2) or (self._frames and len(p) != T):
            want = f"({T}, N, 3), a set per frame" if self._frames else "(N, 3)"
            raise InputError(f"the cull's query points (within) must be {want}, got {p.shape}")
        p = np.ascontiguousarray(p.reshape(T, -1, 3), np.float32)
        if p.shape[1] == 0:
            return first + self.bins, last - self.bins  # empty: no bin at all
        pmin, pmax = (x.numpy() for x in torch.aminmax(torch.from_numpy(p), dim=1))
        if not (np.isfinite(pmin).all() and np.isfinite(pmax).all()):
            raise InputError("the cull's query points (within) have NaN or infinite coordinates")
        # the points' own bin formula is monotone: the bins of the box's corners bound every point's bin
        to_bin = lambda x: np.floor((x - self.low) * self.inv).astype(np.int64)  # noqa: E731
        return np.clip(to_bin(pmin), 0, last), np.clip(to_bin(pmax), 0, last)

    def _rasterize_numpy(self, v32: np.ndarray, t: int) -> None:
        """Frame ``t``'s maps from its vertices ``(V, 3)`` float32 (the reference of the Warp kernel)."""
        tri = v32[self.faces]
        eps = self.eps[t]
        tmin = np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2]) - eps  # (F, 3) widened triangle boxes
        tmax = np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2]) + eps
        lo_bin = np.maximum(self._bin(tmin, t), self.window[0][t])  # the boxes' bins within the query window
        hi_bin = np.minimum(self._bin(tmax, t), self.window[1][t])
        q = tri.astype(np.float64)
        e1, e2 = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]
        normal = np.cross(e1, e2)
        eps, cells = np.float64(eps), 1.0 / self.inv.astype(np.float64)
        low = self.low[t].astype(np.float64)
        for a, (b, c) in enumerate(_PLANE):
            # which rays a triangle can stop: +a if it faces +a (outward), -a if it faces -a (FACING_TOLERANCE)
            nab, nac = e1[:, b] * e2[:, c], e1[:, c] * e2[:, b]
            na = self.orient * (nab - nac) * (-1.0 if a == 1 else 1.0)
            tol = FACING_TOLERANCE * (np.abs(nab) + np.abs(nac))
            # every (triangle, bin) pair of the triangles' boxes, flat: triangle k owns count_k consecutive slots
            wide = np.maximum(hi_bin[:, c] - lo_bin[:, c] + 1, 0)
            count = np.maximum(hi_bin[:, b] - lo_bin[:, b] + 1, 0) * wide
            which = np.repeat(np.arange(len(self.faces)), count)
            local = np.arange(len(which)) - np.repeat(np.cumsum(count) - count, count)
            w = wide[which]
            i, j = lo_bin[which, b] + local // w, lo_bin[which, c] + local % w
            top, bottom = tmax[which, a], tmin[which, a]
            # the plane bound of the kernels (see the module docstring), where the plane is not too steep
            n = normal[which]
            with np.errstate(divide="ignore", invalid="ignore"):
                gb, gc = -n[:, b] / n[:, a], -n[:, c] / n[:, a]
            planar = (na[which] != 0) & (np.abs(gb) + np.abs(gc) <= STEEP)
            gb, gc = np.where(planar, gb, 0.0), np.where(planar, gc, 0.0)
            p0 = q[which, 0]
            a0 = p0[:, a] - gb * p0[:, b] - gc * p0[:, c]
            margin = eps * (2.0 + np.abs(gb) + np.abs(gc)) + 1e-9
            pad = eps + 1e-6 * cells[b]
            bb, cc = low[b] + i * cells[b], low[c] + j * cells[c]  # the bin's lower corner
            # the corners maximising / minimising the plane over the (padded) bin
            up = (a0 + gb * (bb + np.where(gb > 0, cells[b] + pad, -pad)) + margin
                  + gc * (cc + np.where(gc > 0, cells[c] + pad, -pad))).astype(np.float32)
            down = (a0 + gb * (bb + np.where(gb > 0, -pad, cells[b] + pad)) - margin
                    + gc * (cc + np.where(gc > 0, -pad, cells[c] + pad))).astype(np.float32)
            top = np.where(planar, np.minimum(top, up), top)
            bottom = np.where(planar, np.maximum(bottom, down), bottom)
            index = self._base[t, a] + i * self.bins[t, c] + j
            faces_up, faces_down = (na >= -tol)[which], (na <= tol)[which]
            np.maximum.at(self.hi, index[faces_up], top[faces_up])
            np.minimum.at(self.lo, index[faces_down], bottom[faces_down])

    def _bin(self, points: np.ndarray, t: int) -> np.ndarray:
        """Frame ``t``'s bin indices ``(N, 3)`` of float32 points (the kernels' formula, in float32)."""
        return np.floor((points - self.low[t]) * self.inv).astype(np.int64)

    def outside(self, points: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: True where ``points (N, 3)`` (metres) are certainly outside; False: may be inside. After
        an update with ``T`` frames: ``points (T, N, 3)`` -> ``(T, N)``, each frame's points against its mesh."""
        p = np.asarray(points)
        T = len(self.low)
        if p.shape[-1:] != (3,) or p.ndim != (3 if self._frames else 2) or (self._frames and len(p) != T):
            want = f"({T}, N, 3), the frames of the last update" if self._frames else "(N, 3)"
            raise InputError(f"points must be {want}, got {p.shape}")
        p = np.ascontiguousarray(p.reshape(T, -1, 3), np.float32)
        if self.backend == "warp":
            out = np.empty(p.shape[:2], np.uint8)
            if out.size:
                wp = self._wp
                low, high, bins, base, win0, win1 = self._frame_args
                wp.launch(self._query, dim=out.shape, device="cpu",
                          inputs=[wp.array(p, dtype=wp.vec3, device="cpu", copy=False), low, high,
                                  wp.vec3(*self.inv), bins, base, win0, win1, *self._maps,
                                  wp.array(out, dtype=wp.uint8, device="cpu", copy=False)])
            out = out.view(bool)
        else:
            out = np.stack([self._outside_numpy(q, t) for t, q in enumerate(p)])
        return out if self._frames else out[0]

    def _outside_numpy(self, p: np.ndarray, t: int) -> np.ndarray:
        """Frame ``t``'s answer for float32 ``p (N, 3)`` (the reference of the Warp kernel)."""
        out = ((p < self.low[t]) | (p > self.high[t])).any(1)  # outside the box of the mesh's triangles
        near = np.flatnonzero(~out)
        if len(near) == 0:
            return out
        q = p[near]
        k = self._bin(q, t)
        free = np.zeros(len(q), bool)
        mapped = ((k >= self.window[0][t]) & (k <= self.window[1][t])).all(1)  # bins the maps cover
        for a, (b, c) in enumerate(_PLANE):
            index = self._base[t, a] + k[:, b] * self.bins[t, c] + k[:, c]  # a point in the box has a bin
            free |= mapped & ((q[:, a] > self.hi[index]) | (q[:, a] < self.lo[index]))
        out[near] = free
        return out
