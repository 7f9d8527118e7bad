from __future__ import annotations

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.geometry.weight_inpainting import inpainted_skinning_weights, laplacian_for_inpainting
from tests.rig.conftest import sheet


def panel_between_legs():
    """A sheet 1 m wide, 0.8 m tall hanging between two 'legs' (body points along its left and right edges,
    bones 0 and 1) from a 'hip' (points along its top edge, bone 2); plus one triangle far from everything."""
    verts, faces = sheet(21, 11)
    far = np.array([[5.0, 5.0, 5.0], [5.1, 5.0, 5.0], [5.0, 5.1, 5.0]])
    faces = np.concatenate([faces, [[len(verts), len(verts) + 1, len(verts) + 2]]])
    verts = np.concatenate([verts, far])
    t = np.linspace(0.0, 0.79, 40)
    body = np.concatenate([np.stack([np.zeros(40), t, np.zeros(40)], 1), np.stack([np.ones(40), t, np.zeros(40)], 1),
                           np.stack([np.linspace(0.05, 0.95, 40), np.full(40, 0.8), np.zeros(40)], 1)])
    weights = np.repeat(np.eye(3), 40, axis=0)
    return verts, faces, body, weights


def test_weights_are_copied_near_the_body_and_harmonic_elsewhere():
    verts, faces, body, weights = panel_between_legs()
    w, copied = inpainted_skinning_weights(verts, faces, body, weights, max_distance=0.02)
    V = len(verts)
    nearest = np.argmin(np.linalg.norm(verts[:, None] - body[None], axis=-1), 1)
    near = np.linalg.norm(verts - body[nearest], axis=1) <= 0.02
    assert np.array_equal(copied, near)
    np.testing.assert_array_equal(w[copied], weights[nearest[copied]])
    # the far triangle touches no copied vertex: it keeps its closest body vertex's weights
    np.testing.assert_array_equal(w[-3:], weights[nearest[-3:]])
    # brute force: the Laplace equation on the free vertices as one dense solve
    L = laplacian_for_inpainting(verts, faces).toarray()
    free = np.flatnonzero(~copied)[:-3]
    known = np.flatnonzero(copied)
    dense = np.linalg.solve(L[np.ix_(free, free)], -L[np.ix_(free, known)] @ weights[nearest[known]])
    np.testing.assert_allclose(w[free], dense, atol=1e-10)
    assert np.abs(L[free] @ w).max() < 1e-10
    # the maximum principle: weights in [0, 1], rows summing to 1
    assert w.min() > -1e-12 and w.max() < 1 + 1e-12
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-12)


def test_a_hem_between_the_legs_follows_both():
    """Mirrored left-right, the weights swap the legs' bones (the grid's right triangles give the cotangent
    Laplacian the symmetric four-neighbour stencil); the hem's middle takes both legs alike (the closest body
    vertex would give it one leg, or the hip), and the hip's share falls from the top down."""
    verts, faces, body, weights = panel_between_legs()
    w, _ = inpainted_skinning_weights(verts, faces, body, weights, max_distance=0.02)
    grid = verts[:-3]
    mirror = np.array([np.argmin(np.linalg.norm(grid - [1 - x, y, z], axis=1)) for x, y, z in grid])
    np.testing.assert_allclose(w[mirror, 0], w[:len(grid), 1], atol=1e-12)
    middle = np.flatnonzero(np.isclose(grid[:, 0], 0.5))
    middle = middle[np.argsort(grid[middle, 1])]  # bottom to top
    np.testing.assert_allclose(w[middle, 0], w[middle, 1], atol=1e-12)
    assert w[middle[0], 0] > 0.3 and np.all(np.diff(w[middle[:-1], 2]) > 0)


def test_inpainting_bad_input():
    verts, faces, body, weights = panel_between_legs()
    with pytest.raises(InputError, match="must match"):
        inpainted_skinning_weights(verts, faces, body, weights[:-1])
    with pytest.raises(InputError, match="max_distance"):
        inpainted_skinning_weights(verts, faces, body, weights, max_distance=-1.0)
    with pytest.raises(InputError, match="NaN"):
        inpainted_skinning_weights(np.full_like(verts, np.nan), faces, body, weights)
