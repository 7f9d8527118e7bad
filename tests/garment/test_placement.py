"""Reading a garment's up axis and attachment from its geometry, on templates made for the body."""

import numpy as np
import pytest

from loosefit.garment import make_garment
from loosefit.garment.landmarks import measure_body
from loosefit.garment.level_cut import cut_mesh
from loosefit.garment.placement import attachment_type, detect_up, fit_score, to_z_up


@pytest.fixture(scope="module")
def garments(body):
    lm = measure_body(body)
    straps = make_garment("dress", body, seed=2, edge_length=0.05, sleeve_length=0.0)
    v, f, _ = cut_mesh(straps.verts, straps.faces, straps.verts[:, 2] - (lm.armpit_z - 0.05))
    return {
        # A skirt flared at 45 degrees has cloth as slanted at its top as over a shoulder.
        "ring": [make_garment("skirt", body, seed=4, edge_length=0.05, flare=45.0, length=0.5), (v, f)],
        "shoulders": [make_garment("dress", body, seed=6, edge_length=0.05, sleeve_length=0.9)],
        "straps": [straps],
    }


def test_attachment_and_up_axis(garments):
    for kind, items in garments.items():
        for g in items:
            v, f = (g.verts, g.faces) if hasattr(g, "verts") else g
            v = np.asarray(v, np.float64)
            assert attachment_type(v, f) == kind
            y_up = np.stack([v[:, 0], v[:, 2], -v[:, 1]], 1)
            assert detect_up(v, f) == "z" and detect_up(y_up, f) == "y"
            np.testing.assert_allclose(to_z_up(y_up, "y"), v)


def test_up_axis_from_the_longest_flat_loop():
    """A Y-up tube, as a sleeveless jumpsuit's file: a flat hem at y = 0 (1.26 m around) and a longer top opening
    that is not flat (neckline and arm holes in one loop, rising and falling 25 cm twice around; 2.1 m). The top's
    best plane faces z, which misread the file as Z-up; the hem's faces y."""
    theta = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
    hem = np.stack([0.2 * np.cos(theta), np.zeros_like(theta), 0.2 * np.sin(theta)], 1)
    top = np.stack([0.2 * np.cos(theta), 1.0 + 0.25 * np.cos(2.0 * theta), 0.12 * np.sin(theta)], 1)
    n = len(theta)
    i, j = np.arange(n), (np.arange(n) + 1) % n
    faces = np.concatenate([np.stack([i, n + i, j], 1), np.stack([j, n + i, n + j], 1)])
    verts = np.concatenate([hem, top])
    spread = np.linalg.svd(top - top.mean(0), full_matrices=False)
    assert abs(spread[2][-1][2]) > 0.99 and spread[1][2] > 0.5 * spread[1][1]  # facing z, not flat
    assert np.linalg.norm(top - np.roll(top, 1, 0), axis=1).sum() > 1.5 * np.linalg.norm(hem - np.roll(hem, 1, 0), axis=1).sum()
    assert detect_up(verts, faces) == "y"
    # The same file turned Z-up reads as Z-up; a tube with only non-flat openings does not decide.
    assert detect_up(np.stack([verts[:, 0], -verts[:, 2], verts[:, 1]], 1), faces) == "z"
    assert detect_up(np.concatenate([top - [0.0, 1.0, 0.0], top]), faces) is None


def test_fit_score_closed_form():
    # Gaps of the top band 1, 2, 3 cm (median 2 cm, mean deviation 2/3 cm); one point 1 cm inside.
    dist = np.array([0.01, 0.02, 0.03, -0.01, 0.05])
    z = np.array([1.0, 1.0, 0.99, 0.5, 0.4])
    score, top_gap, inside = fit_score(dist, z, band=0.04)
    assert score == pytest.approx(0.02 / 3 + 2.0 * 0.2 + 5.0 * 0.007 / 5)
    assert top_gap == pytest.approx(0.02) and inside == 0.0
