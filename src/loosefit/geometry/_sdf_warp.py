"""Warp kernel of :class:`loosefit.geometry.warp_sdf.MotionMeshSDF` (imported only when Warp loads)."""

import warp as wp

wp.config.quiet = True
wp.init()

#: A barycentric coordinate below this puts the closest point on an edge or a vertex (as BodySDF's).
FEATURE_EPS = wp.constant(wp.float64(1e-7))


@wp.func
def closest_on_triangle(a: wp.vec3d, b: wp.vec3d, c: wp.vec3d, p: wp.vec3d):
    """Barycentric coordinates ``(u, v, w)`` of the point of triangle ``abc`` closest to ``p``, float64 (Ericson's
    regions: exact zeros on an edge or a vertex)."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    if d1 <= zero and d2 <= zero:
        return wp.vec3d(one, zero, zero)
    bp = p - b
    d3 = wp.dot(ab, bp)
    d4 = wp.dot(ac, bp)
    if d3 >= zero and d4 <= d3:
        return wp.vec3d(zero, one, zero)
    vc = d1 * d4 - d3 * d2
    if vc <= zero and d1 >= zero and d3 <= zero:
        v = d1 / (d1 - d3)
        return wp.vec3d(one - v, v, zero)
    cp = p - c
    d5 = wp.dot(ab, cp)
    d6 = wp.dot(ac, cp)
    if d6 >= zero and d5 <= d6:
        return wp.vec3d(zero, zero, one)
    vb = d5 * d2 - d1 * d6
    if vb <= zero and d2 >= zero and d6 <= zero:
        w = d2 / (d2 - d6)
        return wp.vec3d(one - w, zero, w)
    va = d3 * d6 - d5 * d4
    if va <= zero and (d4 - d3) >= zero and (d5 - d6) >= zero:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return wp.vec3d(zero, one - w, w)
    denom = one / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return wp.vec3d(one - v - w, v, w)


@wp.func
def edge_side(pb: wp.float64, pc: wp.float64, ub: wp.float64, uc: wp.float64, vb: wp.float64, vc: wp.float64,
              iu: int, iv: int) -> int:
    """Side (+1 left, -1 right) of the point ``(pb, pc)`` of the directed edge from vertex ``iu`` at ``(ub, uc)`` to
    ``iv`` at ``(vb, vc)``, in a plane. Computed from the edge's lower-numbered end whichever way it is walked (the
    two triangles on an edge get exactly opposite values), and never 0: on the line, the point is moved by
    ``(e, e^2)`` for an infinitesimal ``e`` (a simulation of simplicity), so that a point on an edge or a vertex is
    inside exactly one of the triangles around it. 0 only for an edge of zero length in the plane."""
    flip = int(1)
    b0, c0, b1, c1 = ub, uc, vb, vc
    if iu > iv:
        flip = -1
        b0, c0, b1, c1 = vb, vc, ub, uc
    e = (b1 - b0) * (pc - c0) - (c1 - c0) * (pb - b0)
    if e == wp.float64(0.0):
        e = -(c1 - c0)  # the term in e of the moved point
        if e == wp.float64(0.0):
            e = b1 - b0  # the term in e^2
    if e > wp.float64(0.0):
        return flip
    if e < wp.float64(0.0):
        return -flip
    return 0


@wp.func
def crossing_winding(mesh: wp.uint64, verts: wp.array(dtype=wp.vec3d), faces: wp.array(dtype=wp.int32), vb: int,
                     p: wp.vec3d, a: int, direction: wp.float64, reach: wp.float64) -> int:
    """The winding number of the closed mesh at ``p``: the triangles the ray from ``p`` along axis ``a`` (towards
    ``direction`` = +1 or -1, at most ``reach`` metres) crosses, each +1 where it leaves the solid and -1 where it
    enters (the outward normal's sign along the ray). Exact for a closed mesh, also where it passes through
    itself: the triangles are found in the frame's BVH (float32, boxes widened by 10 um) and tested in float64
    with :func:`edge_side`, so that a ray through an edge or a vertex counts it once."""
    b = (a + 1) % 3
    c = (a + 2) % 3
    lower = wp.vec3(wp.float32(p[0]) - 1.0e-5, wp.float32(p[1]) - 1.0e-5, wp.float32(p[2]) - 1.0e-5)
    upper = wp.vec3(wp.float32(p[0]) + 1.0e-5, wp.float32(p[1]) + 1.0e-5, wp.float32(p[2]) + 1.0e-5)
    if direction > wp.float64(0.0):
        upper[a] = wp.float32(p[a] + reach) + 1.0e-5
    else:
        lower[a] = wp.float32(p[a] - reach) - 1.0e-5
    winding = int(0)
    query = wp.mesh_query_aabb(mesh, lower, upper)
    for f in query:
        i0 = faces[3 * f]
        i1 = faces[3 * f + 1]
        i2 = faces[3 * f + 2]
        q0 = verts[vb + i0]
        q1 = verts[vb + i1]
        q2 = verts[vb + i2]
        s0 = edge_side(p[b], p[c], q1[b], q1[c], q2[b], q2[c], i1, i2)
        s1 = edge_side(p[b], p[c], q2[b], q2[c], q0[b], q0[c], i2, i0)
        s2 = edge_side(p[b], p[c], q0[b], q0[c], q1[b], q1[c], i0, i1)
        if s0 != 0 and s0 == s1 and s1 == s2:
            # where the ray meets the triangle's plane, from the signed areas opposite each corner
            w0 = (q2[b] - q1[b]) * (p[c] - q1[c]) - (q2[c] - q1[c]) * (p[b] - q1[b])
            w1 = (q0[b] - q2[b]) * (p[c] - q2[c]) - (q0[c] - q2[c]) * (p[b] - q2[b])
            w2 = (q1[b] - q0[b]) * (p[c] - q0[c]) - (q1[c] - q0[c]) * (p[b] - q0[b])
            total = w0 + w1 + w2
            if total != wp.float64(0.0):
                hit = (w0 * q0[a] + w1 * q1[a] + w2 * q2[a]) / total
                if direction * (hit - p[a]) > wp.float64(0.0):
                    # counter-clockwise seen down the axis (b, c, a right-handed): the normal points along +a
                    if direction > wp.float64(0.0):
                        winding += s0
                    else:
                        winding -= s0
    return winding


@wp.kernel
def signed_closest(meshes: wp.array(dtype=wp.uint64), verts: wp.array(dtype=wp.vec3d),
                   faces: wp.array(dtype=wp.int32), corner_edge: wp.array(dtype=wp.int32),
                   face_normals: wp.array(dtype=wp.vec3d), edge_normals: wp.array(dtype=wp.vec3d),
                   vertex_normals: wp.array(dtype=wp.vec3d), box_low: wp.array(dtype=wp.vec3d),
                   box_high: wp.array(dtype=wp.vec3d), num_verts: int, num_faces: int, num_edges: int,
                   points: wp.array(dtype=wp.vec3d), frame: wp.array(dtype=wp.int32),
                   outside_beyond: wp.array(dtype=wp.float64), winding_from: wp.float64,
                   dist: wp.array(dtype=wp.float64), closest: wp.array(dtype=wp.vec3d),
                   face: wp.array(dtype=wp.int32)):
    """For point ``i`` of frame ``frame[i]``: the closest triangle from the frame's float32 BVH, then the closest
    point on it, the distance and the pseudonormal side in float64; a point the pseudonormal puts more than
    ``winding_from`` and at most ``outside_beyond[i]`` outside takes its side from the winding number
    (:func:`crossing_winding`, exact; ``box_low``, ``box_high``: each frame's bounding box)."""
    i = wp.tid()
    t = frame[i]
    p = points[i]
    p32 = wp.vec3(wp.float32(p[0]), wp.float32(p[1]), wp.float32(p[2]))
    q = wp.mesh_query_point_no_sign(meshes[t], p32, 1.0e6)
    f = q.face
    i0 = faces[3 * f]
    i1 = faces[3 * f + 1]
    i2 = faces[3 * f + 2]
    vb = t * num_verts
    a = verts[vb + i0]
    b = verts[vb + i1]
    c = verts[vb + i2]
    bary = closest_on_triangle(a, b, c, p)
    x = bary[0] * a + bary[1] * b + bary[2] * c
    d = wp.length(p - x)
    # the normal of the feature holding the closest point (BodySDF._pseudonormal)
    zeros = int(0)
    first_zero = int(-1)
    for k in range(3):
        if bary[k] < FEATURE_EPS:
            zeros += 1
            if first_zero < 0:
                first_zero = k
    normal = face_normals[t * num_faces + f]
    if zeros == 1:
        normal = edge_normals[t * num_edges + corner_edge[3 * f + first_zero]]
    elif zeros >= 2:
        keep = int(0)
        if bary[1] > bary[keep]:
            keep = 1
        if bary[2] > bary[keep]:
            keep = 2
        normal = vertex_normals[vb + faces[3 * f + keep]]
    s = d
    if wp.dot(p - x, normal) < wp.float64(0.0):
        s = -d
    if s > winding_from and s <= outside_beyond[i]:
        # the ray along the axis that leaves the frame's box soonest: the fewest triangles to test
        lo = box_low[t]
        hi = box_high[t]
        best = hi[0] - p[0]
        axis = int(0)
        direction = wp.float64(1.0)
        for k in range(3):
            if hi[k] - p[k] < best:
                best = hi[k] - p[k]
                axis = k
                direction = wp.float64(1.0)
            if p[k] - lo[k] < best:
                best = p[k] - lo[k]
                axis = k
                direction = wp.float64(-1.0)
        if best > wp.float64(0.0) and crossing_winding(meshes[t], verts, faces, vb, p, axis, direction, best) > 0:
            s = -s
    dist[i] = s
    closest[i] = x
    face[i] = f
