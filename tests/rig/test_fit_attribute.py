"""FitGar's fit attribute: distances, even selection, factor analysis against scikit-learn, tight versus loose."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from sklearn.decomposition import FactorAnalysis

from loosefit.errors import InputError
from loosefit.rig.fit_attribute import FitAttributeModel, body_distances, distance_vector, even_selection
from tests.rig.conftest import sheet


def sphere(radius: float, n: int = 40):
    """A UV sphere (``n`` rings of ``2n`` vertices plus poles) of ``radius`` around the origin."""
    theta = np.linspace(0, np.pi, n + 2)[1:-1]
    phi = np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    verts = radius * np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]])
    faces = []
    for j in range(2 * n):
        faces.append((0, 1 + j, 1 + (j + 1) % (2 * n)))
        last = 1 + (n - 1) * 2 * n
        faces.append((len(verts) - 1, last + (j + 1) % (2 * n), last + j))
    for i in range(n - 1):
        for j in range(2 * n):
            a, b = 1 + i * 2 * n + j, 1 + i * 2 * n + (j + 1) % (2 * n)
            faces += [(a, a + 2 * n, b), (b, a + 2 * n, b + 2 * n)]
    return verts, np.array(faces, np.int64)


def test_distances_of_concentric_spheres():
    garment, faces = sphere(0.3, 20)
    body, _ = sphere(0.25, 60)
    d = body_distances(garment, body)
    # closed form 0.05 m, up to the body's vertex spacing (a chord of 1.5 degrees at 0.25 m: ~6.5 mm)
    assert np.all(d >= 0.05 - 1e-6) and np.all(d < 0.05 + 1e-3)
    v = distance_vector(garment, faces, body, 100)
    assert v.shape == (100,) and (np.diff(v) >= 0).all()
    assert np.all(np.abs(v - 0.05) < 1e-3)


def test_even_selection_spreads_vertices():
    verts, faces = sheet(41, 41, jitter=0.3)
    picked = even_selection(verts, faces, 200, seed=1)
    assert len(picked) == 200 and len(np.unique(picked)) == 200
    rand = np.random.default_rng(1).choice(len(verts), 200, replace=False)
    # no two kept vertices closer than the rejection radius sqrt(area / (C n)), C = 3 here (area 1 m^2)
    spacing = cKDTree(verts[picked]).query(verts[picked], k=2)[0][:, 1].min()
    spacing_random = cKDTree(verts[rand]).query(verts[rand], k=2)[0][:, 1].min()
    assert spacing > np.sqrt(1.0 / (3 * 200)) and spacing > 3 * spacing_random
    np.testing.assert_array_equal(even_selection(verts, faces, 5000), np.arange(len(verts)))


def test_fewer_vertices_than_the_length_are_read_as_quantiles():
    garment, faces = sphere(0.3, 6)  # 74 vertices
    body, _ = sphere(0.2, 30)
    v = distance_vector(garment, faces, body, 500)
    d = np.sort(body_distances(garment, body))
    assert v.shape == (500,) and v[0] == pytest.approx(d[0]) and v[-1] == pytest.approx(d[-1])
    assert (np.diff(v) >= 0).all()


def test_transform_is_scikit_learns_posterior_mean():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(12, 3)) @ rng.normal(size=(3, 30)) + rng.normal(scale=0.1, size=(12, 30)) + 1.0
    model = FitAttributeModel.fit(X, factors=3)
    fa = FactorAnalysis(n_components=3, svd_method="lapack", random_state=0).fit(X)
    sign = np.sign((model.components * fa.components_).sum(1))
    np.testing.assert_allclose(model.transform(X), fa.transform(X) * sign, atol=1e-5)
    assert (model.components.sum(1) > 0).all()
    assert FitAttributeModel.fit(X[:3], factors=8).num_factors == 2  # capped at pairs - 1


def test_tight_and_loose_garments_separate_along_the_first_factor(body):
    from loosefit.garment import make_garment

    tight_params = {"edge_length": 0.045, "flare": 2.0, "hip_ease": 0.01, "waist_ease": 0.006}
    loose_params = {"edge_length": 0.045, "flare": 30.0, "hip_ease": 0.08, "waist_ease": 0.03}
    tight = [make_garment("skirt", body, seed=s, **tight_params) for s in range(3)]
    loose = [make_garment("skirt", body, seed=s, **loose_params) for s in range(3)]
    verts = body.rest_verts()
    length = min(len(g.verts) for g in tight + loose)
    X = np.stack([distance_vector(g.verts, g.faces, verts, length) for g in tight + loose])
    model = FitAttributeModel.fit(X, factors=2)
    first = model.transform(X)[:, 0]
    assert first[3:].min() > first[:3].max()  # measured: tight about -0.9, loose 0.5 to 1.8
    # a new pair at run time: a loose skirt of another seed lands on the loose side
    other = make_garment("skirt", body, seed=7, **loose_params)
    assert model.attribute(other.verts, other.faces, verts)[0] > first[:3].max()


def test_model_file_round_trip_and_bad_files(tmp_path):
    X = np.random.default_rng(1).normal(size=(6, 10))
    model = FitAttributeModel.fit(X, factors=2, seed=3)
    model.save(tmp_path / "fa.npz")
    back = FitAttributeModel.load(tmp_path / "fa.npz")
    np.testing.assert_array_equal(back.transform(X), model.transform(X))
    assert back.seed == 3 and back.info == model.info
    (tmp_path / "bad.npz").write_text("garbage")
    with pytest.raises(InputError, match="bad.npz"):
        FitAttributeModel.load(tmp_path / "bad.npz")
    with pytest.raises(InputError, match="length 10"):
        model.transform(np.ones((1, 9)))
    with pytest.raises(InputError, match="2 pairs or more"):
        FitAttributeModel.fit(X[:1])
