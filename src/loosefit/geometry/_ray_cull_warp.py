"""Warp kernels of :mod:`loosefit.geometry.ray_cull` (imported only when Warp loads). Launched on the CPU
only: Warp runs a CPU launch's threads one after another, so the plain read-max-write of the maps in
:func:`rasterize` has no race."""

import warp as wp

wp.config.quiet = True
wp.init()

#: Planes steeper than this (``|da/db| + |da/dc|``) bound a bin by their box alone (see ray_cull.STEEP).
STEEP = wp.constant(wp.float64(20.0))


@wp.func
def bin_of(x: float, low: float, inv: float) -> int:
    return int(wp.floor((x - low) * inv))


@wp.func
def splat(hi: wp.array(dtype=float), lo: wp.array(dtype=float), base: int, stride: int,
          i0: int, i1: int, j0: int, j1: int, top: float, bottom: float,
          n: wp.vec3d, a: int, b: int, c: int, p: wp.vec3d, eps: wp.float64,
          low_b: wp.float64, low_c: wp.float64, cell_b: wp.float64, cell_c: wp.float64):
    # the triangle's plane a = a0 + gb * b + gc * c, when it is not too steep along the ray
    planar = int(0)
    gb = wp.float64(0.0)
    gc = wp.float64(0.0)
    a0 = wp.float64(0.0)
    margin = wp.float64(0.0)
    if wp.abs(n[a]) > wp.float64(0.0):
        gb = -n[b] / n[a]
        gc = -n[c] / n[a]
        if wp.abs(gb) + wp.abs(gc) <= STEEP:
            planar = 1
            a0 = p[a] - gb * p[b] - gc * p[c]
            margin = eps * (wp.float64(2.0) + wp.abs(gb) + wp.abs(gc)) + wp.float64(1e-9)
    pad = eps + wp.float64(1e-6) * cell_b
    # the corners of the (padded) bin that maximise / minimise the plane
    off_b_hi = wp.where(gb > wp.float64(0.0), cell_b + pad, -pad)
    off_b_lo = wp.where(gb > wp.float64(0.0), -pad, cell_b + pad)
    off_c_hi = wp.where(gc > wp.float64(0.0), cell_c + pad, -pad)
    off_c_lo = wp.where(gc > wp.float64(0.0), -pad, cell_c + pad)
    for i in range(i0, i1 + 1):
        row = base + i * stride
        bb = low_b + wp.float64(i) * cell_b
        sb_hi = a0 + gb * (bb + off_b_hi) + margin
        sb_lo = a0 + gb * (bb + off_b_lo) - margin
        for j in range(j0, j1 + 1):
            t = top
            u = bottom
            if planar == 1:
                cc = low_c + wp.float64(j) * cell_c
                t = wp.min(t, float(sb_hi + gc * (cc + off_c_hi)))
                u = wp.max(u, float(sb_lo + gc * (cc + off_c_lo)))
            # Warp runs a CPU launch's threads one after another: the plain read-max-write has no race
            hi[row + j] = wp.max(hi[row + j], t)
            lo[row + j] = wp.min(lo[row + j], u)


@wp.kernel
def rasterize(verts: wp.array2d(dtype=wp.vec3), faces: wp.array(dtype=wp.vec3i), eps: wp.array(dtype=float),
              low: wp.array(dtype=wp.vec3), inv: wp.vec3, bins: wp.array(dtype=wp.vec3i),
              base: wp.array(dtype=wp.vec3i), hi: wp.array(dtype=float), lo: wp.array(dtype=float)):
    """Launched on ``(T, F)``: triangle ``k`` of frame ``t`` into that frame's three maps (starting at ``base[t]``)."""
    t, k = wp.tid()
    f = faces[k]
    p0, p1, p2 = verts[t, f[0]], verts[t, f[1]], verts[t, f[2]]
    e32 = eps[t]
    widen = wp.vec3(e32, e32, e32)
    mn = wp.min(wp.min(p0, p1), p2) - widen
    mx = wp.max(wp.max(p0, p1), p2) + widen
    lw = low[t]
    x0, x1 = bin_of(mn[0], lw[0], inv[0]), bin_of(mx[0], lw[0], inv[0])
    y0, y1 = bin_of(mn[1], lw[1], inv[1]), bin_of(mx[1], lw[1], inv[1])
    z0, z1 = bin_of(mn[2], lw[2], inv[2]), bin_of(mx[2], lw[2], inv[2])
    q0 = wp.vec3d(wp.float64(p0[0]), wp.float64(p0[1]), wp.float64(p0[2]))
    q1 = wp.vec3d(wp.float64(p1[0]), wp.float64(p1[1]), wp.float64(p1[2]))
    q2 = wp.vec3d(wp.float64(p2[0]), wp.float64(p2[1]), wp.float64(p2[2]))
    n = wp.cross(q1 - q0, q2 - q0)
    e = wp.float64(e32)
    lx, ly, lz = wp.float64(lw[0]), wp.float64(lw[1]), wp.float64(lw[2])
    cx = wp.float64(1.0) / wp.float64(inv[0])
    cy = wp.float64(1.0) / wp.float64(inv[1])
    cz = wp.float64(1.0) / wp.float64(inv[2])
    nb = bins[t]
    b = base[t]
    splat(hi, lo, b[0], nb[2], y0, y1, z0, z1, mx[0], mn[0], n, 0, 1, 2, q0, e, ly, lz, cy, cz)  # x rays: (y, z)
    splat(hi, lo, b[1], nb[2], x0, x1, z0, z1, mx[1], mn[1], n, 1, 0, 2, q0, e, lx, lz, cx, cz)  # y rays: (x, z)
    splat(hi, lo, b[2], nb[1], x0, x1, y0, y1, mx[2], mn[2], n, 2, 0, 1, q0, e, lx, ly, cx, cy)  # z rays: (x, y)


@wp.kernel
def query(points: wp.array2d(dtype=wp.vec3), low: wp.array(dtype=wp.vec3), high: wp.array(dtype=wp.vec3),
          inv: wp.vec3, bins: wp.array(dtype=wp.vec3i), base: wp.array(dtype=wp.vec3i),
          hi: wp.array(dtype=float), lo: wp.array(dtype=float), out: wp.array2d(dtype=wp.uint8)):
    """Launched on ``(T, N)``: point ``n`` of frame ``t`` against that frame's maps."""
    t, n = wp.tid()
    p = points[t, n]
    lw = low[t]
    hg = high[t]
    nb = bins[t]
    free = int(0)
    for a in range(3):
        if p[a] < lw[a] or p[a] > hg[a]:
            free = 1
    if free == 0:
        for a in range(3):
            b = int(1)
            c = int(2)
            if a == 1:
                b = 0
            if a == 2:
                b = 0
                c = 1
            k = base[t][a] + bin_of(p[b], lw[b], inv[b]) * nb[c] + bin_of(p[c], lw[c], inv[c])
            if p[a] > hi[k] or p[a] < lo[k]:
                free = 1
    out[t, n] = wp.uint8(free)
