"""The body-shape morph of a fit's drape: linear from one shape's vertices to another's, then held."""

import numpy as np

from loosefit.sim.preroll import morph_frames


def test_morph_is_linear_then_holds():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    frames, weight = morph_frames(a, b, morph=4, settle=3)
    assert frames.shape == (8, 5, 3) and frames.dtype == np.float32
    np.testing.assert_allclose(weight, [0, 0.25, 0.5, 0.75, 1, 1, 1, 1])
    for k in range(8):  # each frame is the straight-line blend at its weight
        np.testing.assert_allclose(frames[k], (1 - weight[k]) * a + weight[k] * b, atol=1e-6)
    np.testing.assert_allclose(frames[0], a, atol=1e-6)
    np.testing.assert_allclose(frames[-1], b, atol=1e-6)
