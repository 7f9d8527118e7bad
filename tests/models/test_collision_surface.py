"""The surface pass of the collision handling (loosefit's addition beyond SwinGar Eq. 10, which moves vertices only):
a limb passing through a triangle or an edge whose vertices are all outside it, on closed-form fields (a sphere,
a cylinder "limb") and on the exact field of a mesh with the cull."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from loosefit.errors import InputError
from loosefit.geometry.ray_cull import AxisRayCuller
from loosefit.geometry.signed_distance import BodySDF
from loosefit.metrics.collision import surface_samples
from loosefit.models.collision import (SURFACE_TOLERANCE, CollisionResolver, ExactSDF, correct_frame,
                                       resolve_collisions, surface_sample_weights)
from tests.rig.conftest import sheet

RADIUS = 0.06
#: The test's bound on what is left inside: the surface pass's tolerance plus float rounding.
LEFT = SURFACE_TOLERANCE + 1e-9


def sphere(x: torch.Tensor) -> torch.Tensor:
    """A ball of radius 6 cm at the origin, negative inside."""
    return x.norm(dim=-1) - RADIUS


def cylinder(x: torch.Tensor) -> torch.Tensor:
    """A limb: an infinite cylinder of radius 6 cm along x through the origin, negative inside."""
    return x[..., 1:].norm(dim=-1) - RADIUS


def coarse_strip(height: float) -> tuple[torch.Tensor, np.ndarray]:
    """A 0.9 m x 0.6 m sheet of 10 cm cells at ``z = height`` whose vertex columns and rows stand at +-5 cm, +-15 cm,
    ... off the axes: at ``height = 4 cm`` every vertex is outside both solids (by 4 mm at the closest, the
    cylinder), and the limb passes through the triangles and edges between the two middle rows (their midpoints
    at ``y = 0`` are 2 cm inside)."""
    verts, faces = sheet(7, 10, width=0.6, height=0.9)
    verts = verts - [0.3, 0.45, 0.0] + [0.0, 0.0, height]
    return torch.from_numpy(verts), faces


def big_triangle() -> tuple[torch.Tensor, np.ndarray]:
    """One triangle of circumradius 30 cm at ``z = 4 cm`` over the sphere: its vertices and edge midpoints (15 cm
    from the axis) are outside, its centroid 2 cm inside."""
    angle = np.deg2rad([90.0, 210.0, 330.0])
    verts = np.stack([0.3 * np.cos(angle), 0.3 * np.sin(angle), np.full(3, 0.04)], 1)
    return torch.from_numpy(verts), np.array([[0, 1, 2]])


def depths(verts: torch.Tensor, faces: np.ndarray, field) -> np.ndarray:
    """The field at the garment's edge midpoints and triangle centroids (the collision metric's surface samples)."""
    return field(torch.from_numpy(surface_samples(verts.numpy(), faces))).numpy()


def test_samples_are_the_metrics_edge_midpoints_and_centroids():
    verts, faces = coarse_strip(0.04)
    index, weight = surface_sample_weights(faces)
    points = (verts.numpy()[index] * weight[..., None]).sum(1)
    np.testing.assert_allclose(points, surface_samples(verts.numpy(), faces), rtol=0, atol=1e-15)
    assert np.allclose(weight.sum(1), 1.0) and len(index) == len(faces) + (len(verts) + len(faces) - 1)  # E = V + F - 1


@pytest.mark.parametrize("field", [sphere, cylinder], ids=["sphere", "cylinder"])
def test_a_limb_through_a_coarse_strip_between_its_vertices_is_resolved(field):
    verts, faces = coarse_strip(0.04)
    assert (field(verts) > 0.003).all()  # every vertex outside
    assert depths(verts, faces, field).min() < -0.015  # but the limb 2 cm through the surface between them
    # SwinGar Eq. 10 alone sees nothing to do
    alone, moved_alone = resolve_collisions(verts, faces, field, surface=False)
    assert torch.equal(alone, verts) and not moved_alone.any()
    out, moved = resolve_collisions(verts, faces, field)
    assert depths(out, faces, field).min() >= -LEFT
    assert (field(out) >= -LEFT).all()
    # only the two rows around the contact move (and only where the limb is, for the sphere): the vertices at
    # |y| >= 15 cm do not move at all, nor (sphere) at |x| >= 20 cm
    near = (verts[:, 1].abs() < 0.1) & ((verts[:, 0].abs() < 0.15) | (field is cylinder))
    assert torch.equal(out[~near], verts[~near])
    assert torch.equal(moved, (out != verts).any(1)) and moved.any()
    if field is cylinder:
        assert torch.equal(moved, near)  # along the whole limb
    else:  # the two over the ball, and the far corners of the two triangles whose centroids are 13 mm in
        assert moved.sum() == 4 and (verts[moved, 0] == 0).sum() == 2
    # moved out, never in: each moved vertex is further from the limb, by at most the 2 cm depth plus the step
    gain = (field(out) - field(verts))[moved]
    assert (gain > 0).all() and float((out - verts).norm(dim=-1).max()) < 0.025


def test_a_big_triangle_over_a_sphere_is_lifted_to_its_surface():
    """No vertex and no edge midpoint inside, the centroid 2 cm in: each vertex moves by the depth times
    ``(1/3) / (3 (1/3)^2) = 1`` along the normal at the centroid (+z): the triangle is lifted 2 cm, the centroid
    lands on the sphere."""
    verts, faces = big_triangle()
    assert (sphere(verts) > 0).all() and depths(verts, faces, sphere)[:3].min() > 0.09
    out, moved = resolve_collisions(verts, faces, sphere)
    assert moved.all()
    torch.testing.assert_close(out - verts, torch.tensor([[0.0, 0.0, 0.02]] * 3, dtype=verts.dtype), rtol=0,
                               atol=1e-12)
    assert float(sphere(out.mean(0, keepdim=True))[0]) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("field", [sphere, cylinder], ids=["sphere", "cylinder"])
def test_a_garment_that_does_not_penetrate_is_returned_unchanged(field):
    """4 mm over the limb at its closest (every sample outside, some within 5 mm): bit for bit the input."""
    verts, faces = coarse_strip(RADIUS + 0.004)
    assert depths(verts, faces, field).min() == pytest.approx(0.004, abs=1e-12)
    out, moved = resolve_collisions(verts, faces, field)
    assert torch.equal(out, verts) and not moved.any()
    # a sample inside by less than the tolerance (cloth resting on the body) is left too
    resting, _ = coarse_strip(RADIUS - 0.5 * SURFACE_TOLERANCE)
    out, moved = resolve_collisions(resting, faces, cylinder)
    assert torch.equal(out, resting) and not moved.any()


def test_the_passes_converge_where_a_curved_limb_needs_several():
    """A strip across the cylinder with its triangles' corners both sides of the top: one pass can leave samples
    it moved next to inside (a vertex lifted along another sample's normal); the passes end with none."""
    verts, faces = sheet(6, 9, width=0.5, height=0.48, jitter=0.3, seed=4)
    verts = torch.from_numpy(verts - [0.25, 0.24, 0.0] + [0.0, 0.0, 0.035])
    one, _ = CollisionResolver(faces, len(verts), passes=1)(verts, cylinder)
    out, _ = CollisionResolver(faces, len(verts))(verts, cylinder)
    assert depths(verts, faces, cylinder).min() < -0.015
    assert depths(out, faces, cylinder).min() >= -LEFT
    assert depths(one, faces, cylinder).min() <= depths(out, faces, cylinder).min()
    # when the passes run out, SwinGar Eq. 10 checks the last moves: no vertex is left inside
    assert (cylinder(one) >= -1e-9).all() and (cylinder(out) >= -1e-9).all()
    with pytest.raises(InputError, match="surface passes"):
        CollisionResolver(faces, len(verts), passes=-1)


def test_exact_field_with_the_cull_resolves_a_triangle_through_a_mesh_limb():
    """The exact field of a cylinder mesh (a closed limb, libigl) with the posed limb's cull: the samples the cull
    proves outside never reach the field, and the result is the one without the cull."""
    limb = trimesh.creation.cylinder(radius=RADIUS, height=1.0, sections=64)
    limb.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0.0, 1.0, 0.0]))  # along x
    body = BodySDF(np.asarray(limb.vertices), np.asarray(limb.faces))
    verts, faces = coarse_strip(0.04)
    world = verts.numpy().astype(np.float32)
    field = ExactSDF(body)
    resolver = CollisionResolver(faces, len(world))
    culler = AxisRayCuller(body.verts, body.faces, 0.0125).update(body.verts, world)
    asked = []

    class Counting(ExactSDF):
        def _query(self, points, *hint):
            asked.append(len(points))
            return super()._query(points, *hint)

    culled, moved = correct_frame(world, resolver, Counting(body), None, culler)
    plain, moved_plain = correct_frame(world, resolver, field, None, None)
    np.testing.assert_allclose(culled, plain, rtol=0, atol=1e-6)
    assert np.array_equal(moved, moved_plain) and moved.sum() == 2 * 7
    assert body.query(surface_samples(culled, faces)).min() >= -LEFT - 1e-6
    unmoved = ~moved
    assert np.array_equal(culled[unmoved], world[unmoved])
    assert max(asked) < len(surface_sample_weights(faces)[0])  # the cull kept most samples from the field


def test_exact_field_trusts_a_known_outside_distance_only_for_its_winding_check():
    """``outside_beyond``: a point farther from the surface than it is known outside (the surface pass knows it
    from a vertex farther out than its distance to the point), and the winding number is not asked. Two spheres
    in one mesh passing through each other: at x = 0.15 a point is inside the first, 5 cm from the second's
    surface whose side faces it (the closest triangle says outside, the winding number inside)."""
    a = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    mesh = BodySDF(np.concatenate([a.vertices, a.vertices + [1.2, 0.0, 0.0]]),
                   np.concatenate([a.faces, a.faces + len(a.vertices)]))
    point = torch.tensor([[0.15, 0.0, 0.0]], dtype=torch.float64)
    field = ExactSDF(mesh)
    plain = float(field.value_and_gradient_fn(point)[0][0])
    assert plain == pytest.approx(-0.05, abs=2e-3)
    # a bound below its distance would say outside (it is only ever given where that is proved): the winding
    # number is skipped; a bound above its distance changes nothing
    assert float(field.value_and_gradient_fn(point, outside_beyond=np.array([0.01]))[0][0]) == pytest.approx(-plain)
    assert float(field.value_and_gradient_fn(point, outside_beyond=np.array([0.2]))[0][0]) == plain
