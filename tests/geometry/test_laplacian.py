"""Connectivity, cotangent Laplacian and mass matrix against hand-computed and closed-form values."""

import numpy as np
import pytest
import trimesh

from loosefit.errors import InputError
from loosefit.geometry.laplacian import (
    adjacency,
    boundary_edges,
    cotangent_laplacian,
    cotangent_laplacian_diagonal,
    edges,
    mass_matrix,
    smoothest_modes,
    uniform_laplacian,
)


def grid(n, h=1.0):
    """(n+1)^2 vertices on z=0 spaced h, two CCW triangles per cell split along (a,b)-(a+1,b+1)."""
    a, b = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    verts = np.stack([a.ravel() * h, b.ravel() * h, np.zeros(a.size)], 1)
    k = lambda i, j: i * (n + 1) + j  # noqa: E731
    faces = [f for i in range(n) for j in range(n) for f in ((k(i, j), k(i + 1, j), k(i + 1, j + 1)), (k(i, j), k(i + 1, j + 1), k(i, j + 1)))]
    return verts, np.array(faces, dtype=np.int64)


def hexagon_fan(radius=1.0):
    """Centre vertex 0 and six ring vertices: six equilateral triangles."""
    ang = np.arange(6) * np.pi / 3
    verts = np.vstack([[0, 0, 0], np.stack([radius * np.cos(ang), radius * np.sin(ang), np.zeros(6)], 1)])
    faces = np.array([[0, 1 + i, 1 + (i + 1) % 6] for i in range(6)])
    return verts, faces


def brute_force_cotmatrix(verts, faces):
    V = len(verts)
    L = np.zeros((V, V))
    for f in faces:
        for k in range(3):
            i, j, o = f[(k + 1) % 3], f[(k + 2) % 3], f[k]
            a, b = verts[i] - verts[o], verts[j] - verts[o]
            w = 0.5 * np.dot(a, b) / np.linalg.norm(np.cross(a, b))
            L[i, j] += w
            L[j, i] += w
    L -= np.diag(L.sum(1))
    return L


def test_edges_boundary_adjacency_of_a_square():
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    assert edges(faces).tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    assert boundary_edges(faces).tolist() == [[0, 1], [0, 3], [1, 2], [2, 3]]
    A = adjacency(faces, 4).toarray()
    assert A.tolist() == [[0, 1, 1, 1], [1, 0, 1, 0], [1, 1, 0, 1], [1, 0, 1, 0]]
    L = uniform_laplacian(faces, 4).toarray()
    assert np.allclose(L.sum(1), 0) and L[0, 0] == -3 and L[1, 1] == -2


def test_cotangent_laplacian_matches_brute_force_on_an_irregular_mesh():
    verts, faces = grid(5)
    rng = np.random.default_rng(0)
    verts = verts + rng.normal(0, 0.15, verts.shape)
    ref = brute_force_cotmatrix(verts, faces)
    assert np.abs(cotangent_laplacian(verts, faces).toarray() - ref).max() < 1e-10
    frames = np.stack([verts, 2.5 * verts])  # uniform scaling leaves cotangents unchanged
    diag = cotangent_laplacian_diagonal(frames, faces)
    assert diag.shape == (2, len(verts))
    assert np.abs(diag - np.diag(ref)).max() < 1e-10


def test_cotangent_weights_of_equilateral_fan_are_closed_form():
    verts, faces = hexagon_fan(0.3)
    L = cotangent_laplacian(verts, faces).toarray()
    cot60 = 1 / np.sqrt(3)
    assert L[0, 0] == pytest.approx(-6 * cot60)  # six spokes, each two 60-degree corners / 2
    assert L[0, 1] == pytest.approx(cot60)
    assert L[1, 2] == pytest.approx(cot60 / 2)  # a rim edge has one triangle
    assert np.allclose(L, L.T) and np.allclose(L.sum(1), 0)
    assert np.linalg.eigvalsh(L).max() < 1e-12  # negative semi-definite


def test_linear_precision_on_flat_grid_interior():
    verts, faces = grid(6, 0.1)
    L = cotangent_laplacian(verts, faces)
    interior = np.flatnonzero((verts[:, 0] > 0.05) & (verts[:, 0] < 0.55) & (verts[:, 1] > 0.05) & (verts[:, 1] < 0.55))
    f = 3 * verts[:, 0] - 2 * verts[:, 1] + 0.5
    assert np.abs((L @ f)[interior]).max() < 1e-12


def test_mass_matrix_sums_to_area_and_sphere_mean_curvature():
    verts, faces = grid(4, 0.25)
    for kind in ("voronoi", "barycentric"):
        assert mass_matrix(verts, faces, kind).diagonal().sum() == pytest.approx(1.0)
    m = trimesh.creation.icosphere(4, radius=2.0)
    v = np.asarray(m.vertices)
    M = mass_matrix(v, m.faces)
    L = cotangent_laplacian(v, m.faces)
    hn = (L @ v) / M.diagonal()[:, None]  # = -2 H n with H = 1/r for a sphere
    assert np.abs(np.linalg.norm(hn, axis=1) - 2 / 2.0).max() < 0.02
    assert (np.einsum("ij,ij->i", hn, v) < 0).all()  # points inward


def test_bad_meshes_are_rejected():
    verts, faces = grid(2)
    with pytest.raises(InputError, match="outside"):
        cotangent_laplacian(verts, faces + 100)
    with pytest.raises(InputError, match="shape"):
        cotangent_laplacian(verts[:, :2], faces)
    with pytest.raises(InputError, match="kind"):
        mass_matrix(verts, faces, "lumped")
    with pytest.raises(InputError, match="NaN"):
        cotangent_laplacian(np.full_like(verts, np.nan), faces)


def test_smoothest_modes_of_a_square_are_its_neumann_cosines():
    """On the unit square (free edges) the Laplacian's eigenpairs are cos(m pi x) cos(n pi y) with
    lambda = pi^2 (m^2 + n^2): 0, then pi^2 twice, then 2 pi^2. The discrete modes come back mass-orthonormal,
    the first constant, the next eigenvalues within 1 % of those, and the second mode's span holds cos(pi x)."""
    verts, faces = grid(40, 1 / 40)
    phi = smoothest_modes(verts, faces, 4)
    M = mass_matrix(verts, faces)
    np.testing.assert_allclose(phi.T @ (M @ phi), np.eye(4), atol=1e-8)
    assert np.ptp(phi[:, 0]) < 1e-8  # constant
    L = -cotangent_laplacian(verts, faces)
    rayleigh = np.einsum("vk,vk->k", phi, L @ phi)  # the eigenvalues (mass-normalised modes)
    np.testing.assert_allclose(rayleigh[1:], np.pi**2 * np.array([1, 1, 2]), rtol=1e-2)
    target = np.cos(np.pi * verts[:, 0])
    target /= np.sqrt(target @ (M @ target))
    in_span = phi[:, 1:3] @ (phi[:, 1:3].T @ (M @ target))
    assert np.sqrt((target - in_span) @ (M @ (target - in_span))) < 0.02
    with pytest.raises(InputError, match="no 1681 smoothest modes"):
        smoothest_modes(verts, faces, len(verts))
