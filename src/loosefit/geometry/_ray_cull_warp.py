"""Warp kernels of :mod:`loosefit.geometry.ray_cull` (imported only when Warp loads). Launched on the CPU
only: Warp runs a CPU launch's threads one after another, so the plain read-max-write of the maps in
:func:`rasterize` has no race."""

import warp as wp

wp.config.quiet = True
wp.init()

#: Planes steeper than this (``|da/db| + |da/dc|``) bound a bin by their box alone (see ray_cull.STEEP).
STEEP = wp.constant(wp.float64(20.0))
#: Relative rounding allowance of a normal component (see ray_cull.FACING_TOLERANCE).
FACING = wp.constant(wp.float64(1e-9))


@wp.func
def bin_of(x: float, low: float, inv: float) -> int:
    return int(wp.floor((x - low) * inv))


@wp.func
def splat(hi: wp.array(dtype=float), lo: wp.array(dtype=float), base: int, stride: int,
          i0: int, i1: int, j0: int, j1: int, top: float, bottom: float,
          q0: wp.vec3d, q1: wp.vec3d, q2: wp.vec3d, orient: wp.float64, a: int, b: int, c: int,
          eps: wp.float64, low_b: wp.float64, low_c: wp.float64, cell_b: wp.float64, cell_c: wp.float64):
    if i0 > i1 or j0 > j1:  # no bin of the query window
        return
    e1 = q1 - q0
    e2 = q2 - q0
    # the normal's a component, outward positive: only a triangle facing +a can stop a +a ray (hi), only one
    # facing -a a -a ray (lo); one within rounding of vertical stops both
    nab = e1[b] * e2[c]
    nac = e1[c] * e2[b]
    na = orient * (nab - nac)
    if a == 1:
        na = -na
    tol = FACING * (wp.abs(nab) + wp.abs(nac))
    up = na >= -tol
    down = na <= tol
    # the triangle's plane a = a0 + gb * b + gc * c, when it is not too steep along the ray
    planar = int(0)
    gb = wp.float64(0.0)
    gc = wp.float64(0.0)
    a0 = wp.float64(0.0)
    margin = wp.float64(0.0)
    if na != wp.float64(0.0):
        n = wp.cross(e1, e2)
        gb = -n[b] / n[a]
        gc = -n[c] / n[a]
        if wp.abs(gb) + wp.abs(gc) <= STEEP:
            planar = 1
            a0 = q0[a] - gb * q0[b] - gc * q0[c]
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
            cc = low_c + wp.float64(j) * cell_c
            # Warp runs a CPU launch's threads one after another: the plain read-max-write has no race
            if up:
                t = top
                if planar == 1:
                    t = wp.min(t, float(sb_hi + gc * (cc + off_c_hi)))
                hi[row + j] = wp.max(hi[row + j], t)
            if down:
                u = bottom
                if planar == 1:
                    u = wp.max(u, float(sb_lo + gc * (cc + off_c_lo)))
                lo[row + j] = wp.min(lo[row + j], u)


@wp.kernel
def rasterize(verts: wp.array2d(dtype=wp.vec3), faces: wp.array(dtype=wp.vec3i), eps: wp.array(dtype=float),
              low: wp.array(dtype=wp.vec3), inv: wp.vec3, bins: wp.array(dtype=wp.vec3i),
              base: wp.array(dtype=wp.vec3i), win0: wp.array(dtype=wp.vec3i), win1: wp.array(dtype=wp.vec3i),
              orient: wp.float64, hi: wp.array(dtype=float), lo: wp.array(dtype=float)):
    """Launched on ``(T, F)``: triangle ``k`` of frame ``t`` into that frame's three maps (starting at ``base[t]``),
    the bins of the window ``win0[t]..win1[t]`` (per axis) only."""
    t, k = wp.tid()
    f = faces[k]
    p0, p1, p2 = verts[t, f[0]], verts[t, f[1]], verts[t, f[2]]
    e32 = eps[t]
    widen = wp.vec3(e32, e32, e32)
    mn = wp.min(wp.min(p0, p1), p2) - widen
    mx = wp.max(wp.max(p0, p1), p2) + widen
    lw = low[t]
    w0 = win0[t]
    w1 = win1[t]
    x0, x1 = wp.max(bin_of(mn[0], lw[0], inv[0]), w0[0]), wp.min(bin_of(mx[0], lw[0], inv[0]), w1[0])
    y0, y1 = wp.max(bin_of(mn[1], lw[1], inv[1]), w0[1]), wp.min(bin_of(mx[1], lw[1], inv[1]), w1[1])
    z0, z1 = wp.max(bin_of(mn[2], lw[2], inv[2]), w0[2]), wp.min(bin_of(mx[2], lw[2], inv[2]), w1[2])
    q0 = wp.vec3d(wp.float64(p0[0]), wp.float64(p0[1]), wp.float64(p0[2]))
    q1 = wp.vec3d(wp.float64(p1[0]), wp.float64(p1[1]), wp.float64(p1[2]))
    q2 = wp.vec3d(wp.float64(p2[0]), wp.float64(p2[1]), wp.float64(p2[2]))
    e = wp.float64(e32)
    lx, ly, lz = wp.float64(lw[0]), wp.float64(lw[1]), wp.float64(lw[2])
    cx = wp.float64(1.0) / wp.float64(inv[0])
    cy = wp.float64(1.0) / wp.float64(inv[1])
    cz = wp.float64(1.0) / wp.float64(inv[2])
    nb = bins[t]
    b = base[t]
    splat(hi, lo, b[0], nb[2], y0, y1, z0, z1, mx[0], mn[0], q0, q1, q2, orient, 0, 1, 2, e, ly, lz, cy, cz)  # x rays
    splat(hi, lo, b[1], nb[2], x0, x1, z0, z1, mx[1], mn[1], q0, q1, q2, orient, 1, 0, 2, e, lx, lz, cx, cz)  # y rays
    splat(hi, lo, b[2], nb[1], x0, x1, y0, y1, mx[2], mn[2], q0, q1, q2, orient, 2, 0, 1, e, lx, ly, cx, cy)  # z rays


@wp.kernel
def query(points: wp.array2d(dtype=wp.vec3), low: wp.array(dtype=wp.vec3), high: wp.array(dtype=wp.vec3),
          inv: wp.vec3, bins: wp.array(dtype=wp.vec3i), base: wp.array(dtype=wp.vec3i),
          win0: wp.array(dtype=wp.vec3i), win1: wp.array(dtype=wp.vec3i),
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
        k = wp.vec3i(bin_of(p[0], lw[0], inv[0]), bin_of(p[1], lw[1], inv[1]), bin_of(p[2], lw[2], inv[2]))
        w0 = win0[t]
        w1 = win1[t]
        inside_window = int(1)
        for a in range(3):
            if k[a] < w0[a] or k[a] > w1[a]:
                inside_window = 0
        # a point in a bin the maps left out proves nothing: it stays a candidate
        if inside_window == 1:
            # the y rays first (front and back: on a body they free the most points), then x, then z
            for s in range(3):
                if free == 0:
                    a = int(1)
                    b = int(0)
                    c = int(2)
                    if s == 1:
                        a = 0
                        b = 1
                    if s == 2:
                        a = 2
                        b = 0
                        c = 1
                    m = base[t][a] + k[b] * nb[c] + k[c]
                    if p[a] > hi[m] or p[a] < lo[m]:
                        free = 1
    out[t, n] = wp.uint8(free)
