"""Inflating a body patch and pushing a garment out of the body."""

import numpy as np

from loosefit.garment import make_garment
from loosefit.garment.fitting import inflate, orient_outward, push_out
from loosefit.garment.landmarks import measure_body
from loosefit.garment.level_cut import cut_mesh
from loosefit.garment.mesh_checks import unique_edges


def test_push_out_clears_vertices_and_edge_midpoints(body):
    lm = measure_body(body)
    g = make_garment("skirt", body, seed=3, edge_length=0.04)
    v = g.verts.astype(np.float64)
    v[:, :2] *= 0.8
    assert lm.sdf.query(v).min() < -0.005
    out = push_out(v, g.faces, lm.sdf, 0.006)
    edges, _, _ = unique_edges(g.faces)
    assert lm.sdf.query(out).min() >= 0.006 - 1e-4
    assert lm.sdf.query(0.5 * (out[edges[:, 0]] + out[edges[:, 1]])).min() >= 0.006 - 1e-4
    # Vertices already clear of the body far away from the hips stay where they were.
    far = lm.sdf.query(v) > 0.05
    assert np.abs(out[far] - v[far]).max() < 0.02


def test_inflate_lifts_a_body_patch_to_the_ease(body):
    lm = measure_body(body)
    v, f, _ = cut_mesh(lm.verts, lm.faces, np.abs(lm.verts[:, 2] - 1.0) - 0.1)  # a torso band
    keep = np.abs(v[:, 0]) < 0.3
    f = f[keep[f].all(1)]
    lifted = inflate(v, f, lm.sdf, np.full(len(v), 0.02))
    d = lm.sdf.query(lifted[np.unique(f)])
    assert d.min() > 0.019 and np.median(d) < 0.03
    assert np.array_equal(orient_outward(lifted, f, lm.sdf), f)
    assert np.array_equal(orient_outward(lifted, f[:, ::-1], lm.sdf), f)
