"""Garment templates: every kind over several seeds is one connected, edge-manifold, outward
oriented mesh of well-shaped triangles, clear of the body, within its vertex budget, pinned at the
waist or shoulders; seeds differ, parameters can be set, bad values are refused.

Vertex budget: a mesh of near-equilateral triangles of edge ``h``, area ``A`` and boundary length
``P`` has about ``V = A / (0.866 h^2) + P / (2 h)`` vertices (Euler: ``V = F / 2 + B / 2 + chi``
with ``F = A / (0.433 h^2)`` faces and ``B = P / h`` boundary vertices).
"""

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.garment import KINDS, PARAMS, draw_params, make_garment
from loosefit.garment.landmarks import measure_body
from loosefit.garment.mesh_checks import boundary_loops, face_areas, mesh_report, triangle_angles, unique_edges

SEEDS = (0, 1, 2, 3)
LOOPS = {"skirt": 2, "dress": 4, "long_shirt": 4, "jumpsuit": 5}  # waist+hem; neck+2 arms+hem; +2 legs


@pytest.fixture(scope="module")
def landmarks(body):
    return measure_body(body)


@pytest.fixture(scope="module")
def garments(body):
    """Every kind at the default edge length (0.02 m) for SEEDS, plus a fine and a coarse one."""
    out = {(kind, seed, 0.02): make_garment(kind, body, seed=seed) for kind in KINDS for seed in SEEDS}
    out[("skirt", 5, 0.009)] = make_garment("skirt", body, seed=5, edge_length=0.009)
    out[("jumpsuit", 5, 0.045)] = make_garment("jumpsuit", body, seed=5, edge_length=0.045)
    return out


def test_topology(garments):
    for (kind, seed, h), g in garments.items():
        report = mesh_report(g.verts, g.faces)
        assert report.ok, (kind, seed, h, report)
        assert report.num_boundary_loops == LOOPS[kind], (kind, seed)
        assert g.verts.dtype == np.float32 and g.faces.dtype == np.int64


def test_triangle_shape_and_edge_length(garments):
    for (kind, seed, h), g in garments.items():
        angles = triangle_angles(g.verts, g.faces).min(1)
        assert angles.min() > 5.0, (kind, seed, h, angles.min())
        assert np.percentile(angles, 1) > 20.0, (kind, seed, h)
        edges, _, _ = unique_edges(g.faces)
        length = np.linalg.norm(g.verts[edges[:, 0]] - g.verts[edges[:, 1]], axis=1)
        assert 0.85 * h < length.mean() < 1.15 * h, (kind, seed, h, length.mean())


def test_vertex_budget(garments):
    for (kind, seed, h), g in garments.items():
        area = face_areas(g.verts, g.faces).sum()
        border = sum(np.linalg.norm(g.verts[loop] - g.verts[np.roll(loop, 1)], axis=1).sum() for loop in boundary_loops(g.faces))
        expected = area / (0.866 * h * h) + border / (2 * h)
        # Narrow parts (straps about one edge wide at coarse resolutions) need a few more.
        assert 0.85 * expected < g.num_verts < 1.3 * expected, (kind, seed, h, g.num_verts, expected)
    assert 1000 <= garments[("jumpsuit", 5, 0.045)].num_verts < 2000
    assert garments[("skirt", 5, 0.009)].num_verts > 10000
    for kind in KINDS:
        assert 1500 < garments[(kind, 0, 0.02)].num_verts < 9000


def test_clear_of_the_body(garments, landmarks):
    for (kind, seed, h), g in garments.items():
        edges, _, _ = unique_edges(g.faces)
        mids = 0.5 * (g.verts[edges[:, 0]] + g.verts[edges[:, 1]])
        assert landmarks.sdf.query(g.verts).min() > 0.003, (kind, seed, h)
        assert landmarks.sdf.query(mids).min() > 0.003, (kind, seed, h)


def test_normals_point_away_from_the_body(garments, landmarks):
    for (kind, seed, h), g in garments.items():
        tri = g.verts[g.faces].astype(np.float64)
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        centroid = tri.mean(1)
        _, close, _ = landmarks.sdf.closest(centroid)
        away = np.einsum("ij,ij->i", normal, centroid - close) > 0
        area = face_areas(g.verts, g.faces)
        assert area[away].sum() > 0.95 * area.sum(), (kind, seed, h)


def test_pinned_at_waist_or_shoulders(garments, landmarks):
    for (kind, seed, h), g in garments.items():
        z = g.verts[g.pinned, 2]
        assert g.pinned.sum() >= 10, (kind, seed, h)
        waist = landmarks.waist_z + g.params["waist_offset"]
        if kind == "skirt":
            assert z.min() > waist - 0.05 and z.max() < waist + 0.005
            top_ring = g.verts[:, 2] > waist - 1e-4
            assert g.pinned[top_ring].all()  # the whole waistband edge
        elif kind == "jumpsuit":
            at_waist = np.abs(z - waist) <= max(0.02, 1.5 * h) / 2
            assert at_waist.sum() >= 20 and (z[~at_waist] > landmarks.armpit_z).all()
        else:
            assert z.min() > landmarks.armpit_z + 0.05
            xs = g.verts[g.pinned, 0]
            assert (xs > 0.03).any() and (xs < -0.03).any()  # both shoulders


def test_seeds_give_different_garments(garments):
    for kind in KINDS:
        shapes = [garments[(kind, s, 0.02)] for s in SEEDS]
        for a in range(len(shapes)):
            for b in range(a + 1, len(shapes)):
                ga, gb = shapes[a], shapes[b]
                assert ga.params != gb.params
                assert ga.num_verts != gb.num_verts or not np.allclose(ga.verts, gb.verts, atol=0.01)


def test_same_seed_same_garment(body, garments):
    again = make_garment("skirt", body, seed=1)
    first = garments[("skirt", 1, 0.02)]
    assert np.array_equal(again.verts, first.verts) and np.array_equal(again.faces, first.faces)


def test_parameters_by_keyword(body, landmarks):
    g = make_garment("skirt", body, seed=4, length=0.3, flare=0.0, hem_slope=0.0, hem_irregularity=0.0, waist_offset=0.0)
    assert g.params["length"] == 0.3 and g.params["flare"] == 0.0
    other = draw_params("skirt", 4)
    assert g.params["hip_ease"] == other["hip_ease"]  # the others are still drawn from the seed
    # Flat hem 0.3 m below the waist.
    assert abs(g.verts[:, 2].min() - (landmarks.waist_z - 0.3)) < 0.003
    assert abs(g.verts[:, 2].max() - landmarks.waist_z) < 0.003


def test_params_cover_the_documented_ranges():
    for kind in KINDS:
        values = [draw_params(kind, s) for s in range(40)]
        for name, spec in PARAMS[kind].items():
            drawn = np.array([v[name] for v in values])
            lo, hi = spec.allowed
            assert (drawn >= lo).all() and (drawn <= hi).all(), (kind, name)
            assert np.unique(drawn).size > 5, (kind, name)  # continuous, drawn per seed


@pytest.mark.parametrize(
    "kind, kwargs, message",
    [
        ("cape", {}, "unknown garment kind"),
        ("skirt", {"sleeve_length": 0.3}, "unknown skirt parameter"),
        ("dress", {"flare": 80.0}, "outside"),
        ("skirt", {"length": "long"}, "not a number"),
        ("skirt", {"edge_length": 0.001}, "edge_length"),
        ("skirt", {"length": 1.2, "waist_offset": 0.0}, "below the floor"),
    ],
)
def test_bad_parameters(body, kind, kwargs, message):
    with pytest.raises(InputError, match=message):
        make_garment(kind, body, **kwargs)
