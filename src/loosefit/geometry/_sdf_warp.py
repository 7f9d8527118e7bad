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


@wp.kernel
def signed_closest(meshes: wp.array(dtype=wp.uint64), verts: wp.array(dtype=wp.vec3d),
                   faces: wp.array(dtype=wp.int32), corner_edge: wp.array(dtype=wp.int32),
                   face_normals: wp.array(dtype=wp.vec3d), edge_normals: wp.array(dtype=wp.vec3d),
                   vertex_normals: wp.array(dtype=wp.vec3d), num_verts: int, num_faces: int, num_edges: int,
                   points: wp.array(dtype=wp.vec3d), frame: wp.array(dtype=wp.int32),
                   outside_beyond: wp.array(dtype=wp.float64), winding_from: wp.float64,
                   dist: wp.array(dtype=wp.float64), closest: wp.array(dtype=wp.vec3d),
                   face: wp.array(dtype=wp.int32)):
    """For point ``i`` of frame ``frame[i]``: the closest triangle from the frame's float32 BVH, then the closest
    point on it, the distance and the pseudonormal side in float64; a point the pseudonormal puts more than
    ``winding_from`` and at most ``outside_beyond[i]`` outside takes its side from the winding number."""
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
        w = wp.mesh_query_point_sign_winding_number(meshes[t], p32, 1.0e6, 2.0, 0.5)
        if w.result and w.sign < 0.0:
            s = -s
    dist[i] = s
    closest[i] = x
    face[i] = f
