"""The spectral descriptor: invariances and discrimination as numbers, the Nystrom extension, errors."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scipy.spatial.distance import cdist

from loosefit.errors import InputError
from loosefit.geometry.geodesic import edge_geodesics
from loosefit.rig.spectral import DEFAULT_SIGMA, affinity, descriptor_distance, spectral_decomposition, spectral_descriptor
from tests.rig.conftest import hex_sheet, sheet, tube

KINDS = ("skirt", "dress", "long_shirt", "jumpsuit")


@pytest.fixture(scope="module")
def kinds(body):
    """One garment of each template kind (same seed, 0.04 m edges), and the dress again with 0.03 m edges."""
    from loosefit.garment import make_garment

    out = {kind: make_garment(kind, body, seed=0, edge_length=0.04) for kind in KINDS}
    out["dress_fine"] = make_garment("dress", body, seed=0, edge_length=0.03)
    return out


def roll(verts: np.ndarray, radius: float) -> np.ndarray:
    """Bend a sheet in the XY plane around an axis parallel to Y: an exact isometry."""
    a = verts[:, 0] / radius
    return np.stack([radius * np.sin(a), verts[:, 1], radius * (1 - np.cos(a))], 1)


def fold(verts: np.ndarray, at: float, radius: float) -> np.ndarray:
    """Fold a sheet in the XY plane back over itself: flat for ``x <= at``, then half a cylinder of ``radius``
    about an axis parallel to Y, then flat again ``2 radius`` above the first part (an exact isometry)."""
    x, out, arc_length = verts[:, 0], verts.copy(), np.pi * radius
    arc, back = (x > at) & (x <= at + arc_length), x > at + arc_length
    t = (x[arc] - at) / radius
    out[arc, 0], out[arc, 2] = at + radius * np.sin(t), radius * (1 - np.cos(t))
    out[back, 0], out[back, 2] = at - (x[back] - at - arc_length), 2 * radius
    return out


def test_descriptor_is_a_normalised_spectrum():
    verts, faces = sheet(30, 24)
    d = spectral_descriptor(verts, faces, samples=64)
    assert d.shape == (64,) and d.dtype == np.float32
    assert abs(d.sum() - 1.0) < 1e-5  # trace of S B S = sum of the cell weights
    assert (np.diff(d) <= 0).all()


def test_invariances_against_discrimination_between_kinds(kinds):
    d = {name: spectral_descriptor(g.verts, g.faces) for name, g in kinds.items()}
    dress = kinds["dress"]
    R = Rotation.from_rotvec([0.3, 1.0, -0.5]).as_matrix()
    rigid = descriptor_distance(d["dress"], spectral_descriptor(dress.verts @ R.T + [0.5, -2.0, 1.0], dress.faces))
    remesh = descriptor_distance(d["dress"], d["dress_fine"])
    between = [descriptor_distance(d[a], d[b]) for a, b in itertools.combinations(KINDS, 2)]
    assert rigid < 1e-6
    assert remesh < 0.005  # measured 1.4e-3 (1,577 versus 2,615 vertices)
    assert min(between) > 10 * remesh  # measured: closest kinds (dress, jumpsuit) 0.067, farthest 0.30


def test_isometric_bending_changes_little():
    # An irregular triangulation: on a regular grid, ties between equally far samples are broken
    # by rounding and the rolled sheet gets other samples (2e-3 then).
    verts, faces = sheet(40, 32, jitter=0.3)
    flat = spectral_descriptor(verts, faces, samples=128)
    rolled = descriptor_distance(flat, spectral_descriptor(roll(verts, 0.25), faces, samples=128))
    other = descriptor_distance(flat, spectral_descriptor(*sheet(40, 32, width=1.3, jitter=0.3), samples=128))
    assert rolled < 1e-3  # measured 1.3e-4 (edges become chords: 4e-4 shorter)
    assert other > 50 * rolled  # measured 7e-2 for a 30% wider sheet


def test_euclidean_and_geodesic_agree_on_a_plane_up_to_dijkstra():
    """On a flat sheet the surface distance is the straight line, so the two descriptors differ only by
    Dijkstra's over-estimate. Both use the same samples and cell weights ``w``, so by the Hoffman-Wielandt
    inequality their distance is at most ``sqrt(sum_ij w_i w_j (B_ij - B'_ij)^2)``, and, as the kernel's slope
    is at most ``1 / (sigma sqrt(e))`` and ``sum_ij w_i w_j = 1``, at most ``max_ij (d_ij - |x_i - x_j|) / (sigma
    sqrt(e))``. Near-equilateral triangles (1,558 vertices, 64 samples): Dijkstra over-estimates the distance
    between samples by up to 12.5 cm (15.7 %); measured descriptor distance 0.0359, first bound 0.0387, second
    0.252; a sheet 30 % wider is 0.070 away."""
    verts, faces = hex_sheet()
    geo = spectral_decomposition(verts, faces, samples=64)
    euc = spectral_decomposition(verts, faces, samples=64, distance="euclidean")
    np.testing.assert_array_equal(geo.samples, euc.samples)
    np.testing.assert_array_equal(geo.cell_weights, euc.cell_weights)
    assert geo.distance == "geodesic" and euc.distance == "euclidean"
    s, w = geo.samples, geo.cell_weights
    dijkstra = np.asarray(edge_geodesics(verts, faces, sources=s), np.float64)[:, s]
    straight = cdist(verts[s], verts[s])
    np.testing.assert_allclose(euc.affinity_to_samples[s], affinity(straight, DEFAULT_SIGMA), atol=1e-12)
    over = dijkstra - straight
    assert over.min() > -1e-6 and 0.10 < over.max() < 0.15  # edge paths are never shorter than the line
    diff = affinity(dijkstra, DEFAULT_SIGMA) - affinity(straight, DEFAULT_SIGMA)
    hoffman_wielandt = np.sqrt((w[:, None] * w[None] * diff**2).sum())
    slope = over.max() / (DEFAULT_SIGMA * np.sqrt(np.e))
    measured = descriptor_distance(geo.descriptor(), euc.descriptor())
    assert measured <= hoffman_wielandt <= slope
    assert 0.03 < measured < 0.04 and hoffman_wielandt < 0.045
    wider = verts * [1.3, 1.0, 1.0]
    assert descriptor_distance(geo.descriptor(), spectral_descriptor(wider, faces, samples=64)) > 1.5 * measured
    # a Gaussian of straight-line distances is a positive definite kernel: no negative eigenvalue (the geodesic
    # affinity has some, down to -3e-3 here)
    assert euc.eigenvalues.min() > -1e-9 and geo.eigenvalues.min() < -1e-3


def test_bending_moves_the_euclidean_descriptor_not_the_geodesic():
    """The same sheet rolled (radius 0.25 m, 229 degrees) and folded over itself (radius 5 cm): both keep every
    length within the sheet, only the chords of the bent edges are shorter (by at most 0.07 % and 1.7 %, so
    geodesics shrink by at most that fraction ``eps`` and, with the same samples, each affinity moves by at most
    ``2 eps / e``: 5e-4 and 1.2e-2). Measured, 64 samples: rolled, geodesic 1.0e-4 against Euclidean 0.051;
    folded, geodesic 1.4e-3 against Euclidean 0.156 (the folded layers are 10 cm apart in space, up to 1.2 m
    along the sheet)."""
    verts, faces = hex_sheet()
    flat = {d: spectral_descriptor(verts, faces, samples=64, distance=d) for d in ("geodesic", "euclidean")}
    flat_gap = descriptor_distance(flat["geodesic"], flat["euclidean"])
    moved = {}
    for name, bent in (("rolled", roll(verts, 0.25)), ("folded", fold(verts, 0.4, 0.05))):
        for d in ("geodesic", "euclidean"):
            moved[name, d] = descriptor_distance(flat[d], spectral_descriptor(bent, faces, samples=64, distance=d))
    assert moved["rolled", "geodesic"] < 5e-4 and moved["folded", "geodesic"] < 3e-3, moved
    assert moved["rolled", "euclidean"] > 0.04 and moved["folded", "euclidean"] > 0.12, moved
    for name in ("rolled", "folded"):
        assert moved[name, "euclidean"] > 50 * moved[name, "geodesic"], moved
    # folding changes the Euclidean descriptor four times more than Dijkstra's over-estimate separates the two
    assert moved["folded", "euclidean"] > 4 * flat_gap


def test_simulated_garment_frame_stays_close(simulated_skirt, kinds):
    """Cloth bends a lot but stretches little: the descriptor of a simulated frame stays near the rest one."""
    garment, frames, _ = simulated_skirt
    rest = spectral_descriptor(garment.verts, garment.faces)
    moved = descriptor_distance(rest, spectral_descriptor(frames[-1], garment.faces))
    d = {name: spectral_descriptor(g.verts, g.faces) for name, g in kinds.items() if name != "dress_fine"}
    between = min(descriptor_distance(d[a], d[b]) for a, b in itertools.combinations(d, 2))
    assert moved < between / 2


def test_nystrom_matches_the_full_affinity_spectrum():
    """Against the exact N x N geodesic affinity of a small tube (240 vertices, 40 samples)."""
    verts, faces = tube(rings=12, around=20)
    full = affinity(edge_geodesics(verts, faces), 0.3)
    dec = spectral_decomposition(verts, faces, samples=40, sigma=0.3)
    np.testing.assert_allclose(dec.affinity_to_samples, full[:, dec.samples], atol=1e-12)
    assert abs(dec.cell_weights.sum() - 1.0) < 1e-12
    lam, U = np.linalg.eigh(full)
    lam, U = lam[::-1], U[:, ::-1]
    # N times the descriptor estimates the eigenvalues of A (measured within 6% for the first six)
    np.testing.assert_allclose(len(verts) * dec.eigenvalues[:6], lam[:6], rtol=0.08)
    f = dec.extended_eigenvectors(3)
    np.testing.assert_allclose(f[dec.samples], dec.eigenvectors[:, :3] / np.sqrt(dec.cell_weights)[:, None], atol=1e-9)
    assert abs(np.corrcoef(f[:, 0], U[:, 0])[0, 1]) > 0.99
    # eigenvalues 2 and 3 are equal (the tube's symmetry): compare the plane they span
    q, _ = np.linalg.qr(f[:, 1:3] - f[:, 1:3].mean(0))
    assert np.linalg.norm(U[:, 1:3].T @ q) ** 2 / 2 > 0.9


def test_kernel_and_bad_input():
    np.testing.assert_allclose(affinity([0.0, 0.3, 0.6], 0.3), np.exp([0.0, -0.5, -2.0]))
    verts, faces = tube(rings=3, around=6)
    with pytest.raises(InputError, match="samples"):
        spectral_descriptor(verts, faces, samples=len(verts) + 1)
    with pytest.raises(InputError, match="sigma"):
        spectral_descriptor(verts, faces, sigma=0.0)
    with pytest.raises(InputError, match="distance must be one of"):
        spectral_descriptor(verts, faces, samples=4, distance="heat")
    with pytest.raises(InputError, match="different lengths"):
        descriptor_distance(np.ones(3), np.ones(4))
    with pytest.raises(InputError, match="numerically zero"):
        spectral_decomposition(verts, faces, samples=len(verts), sigma=10.0).extended_eigenvectors(len(verts))
