"""Warp kernel of :meth:`loosefit.geometry.signed_distance.BodySDF.inside` (imported only when Warp loads)."""

import warp as wp

wp.config.quiet = True
wp.init()


@wp.kernel
def winding_inside(mesh: wp.uint64, points: wp.array(dtype=wp.vec3), inside: wp.array(dtype=wp.uint8)):
    """``inside[i] = 1`` where the mesh's generalised winding number at ``points[i]`` exceeds 1/2 (Warp's fast
    winding number: a hierarchy of dipole expansions, accuracy 2)."""
    i = wp.tid()
    query = wp.mesh_query_point_sign_winding_number(mesh, points[i], 1.0e6, 2.0, 0.5)
    if query.result and query.sign < 0.0:
        inside[i] = wp.uint8(1)
    else:
        inside[i] = wp.uint8(0)
