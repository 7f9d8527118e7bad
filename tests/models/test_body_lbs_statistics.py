"""The body-LBS baseline's skinning-weight buffer (:func:`loosefit.sim.attach.garment_weights`, what
:meth:`BodyLBS.init_from_data` copies) against a brute-force nearest rest body vertex, on garment points
around the default Anny body."""

from __future__ import annotations

import numpy as np

from loosefit.sim.attach import garment_weights


def test_each_garment_vertex_takes_the_weights_of_its_nearest_rest_body_vertex(body):
    rest = body.rest_verts()
    rng = np.random.default_rng(0)
    picks = rng.choice(len(rest), 40, replace=False)
    points = rest[picks] + rng.normal(0, 0.01, (40, 3))  # a loose garment's vertices near the skin
    weights = garment_weights(points, body)
    all_weights = body.skinning_weights()
    assert weights.shape == (40, all_weights.shape[1])
    for p, w in zip(points, weights):
        nearest = int(np.argmin(((rest - p) ** 2).sum(-1)))
        np.testing.assert_array_equal(w, all_weights[nearest])
    np.testing.assert_allclose(weights.sum(1), 1.0, atol=1e-5)
    assert len({tuple(np.flatnonzero(w > 0.5)) for w in weights}) > 3  # the points follow different joints
