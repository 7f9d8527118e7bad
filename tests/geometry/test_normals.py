"""Face areas and normals, vertex normals: closed forms, libigl, batching."""

import igl
import numpy as np
import pytest
import trimesh

from loosefit.geometry.normals import face_areas, face_normals, vertex_normals


def test_triangle_normal_and_area_follow_right_hand_rule():
    verts = np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0]], dtype=np.float32)
    faces = np.array([[0, 1, 2]])
    assert np.allclose(face_normals(verts, faces), [[0, 0, 1]])
    assert np.allclose(face_normals(verts, faces[:, ::-1]), [[0, 0, -1]])
    assert face_areas(verts, faces)[0] == pytest.approx(1.0)
    assert face_normals(verts, faces).dtype == np.float32


def test_vertex_normals_of_sphere_are_radial_and_match_libigl():
    m = trimesh.creation.icosphere(3, radius=0.7)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    n = vertex_normals(v, f)
    assert np.abs(n - v / 0.7).max() < 0.02  # polyhedral approximation of the sphere
    ref_area = igl.per_vertex_normals(v, f, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_AREA)
    ref_uniform = igl.per_vertex_normals(v, f, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_UNIFORM)
    assert np.abs(n - ref_area).max() < 1e-6
    assert np.abs(vertex_normals(v, f, "uniform") - ref_uniform).max() < 1e-6


def test_batched_frames_equal_per_frame_results():
    m = trimesh.creation.icosphere(2)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    rng = np.random.default_rng(1)
    frames = v[None] + rng.normal(0, 0.05, (4, len(v), 3))
    batched = vertex_normals(frames, f)
    assert batched.shape == (4, len(v), 3)
    for t in range(4):
        assert np.abs(batched[t] - vertex_normals(frames[t], f)).max() < 1e-6
        assert np.abs(face_normals(frames, f)[t] - face_normals(frames[t], f)).max() < 1e-6
    assert face_areas(frames[None], f).shape == (1, 4, len(f))


def test_degenerate_face_and_unused_vertex_get_zero_normals():
    verts = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [5, 5, 5]], dtype=np.float64)  # collinear + unused
    faces = np.array([[0, 1, 2]])
    assert np.allclose(face_normals(verts, faces), 0)
    assert np.allclose(vertex_normals(verts, faces), 0)


def test_torch_front_end_matches_numpy_and_differentiates():
    """The torch front-end runs the NumPy one's routine: the same normals (batched, both weightings), gradients
    that agree with finite differences, and a finite gradient through a degenerate face."""
    import torch

    from loosefit.geometry.normals import face_normals_torch, vertex_normals_torch

    m = trimesh.creation.icosphere(2)
    rng = np.random.default_rng(2)
    frames = np.asarray(m.vertices)[None] + rng.normal(0, 0.05, (3, len(m.vertices), 3))
    f = np.asarray(m.faces)
    x, ft = torch.from_numpy(frames), torch.from_numpy(f).long()
    for weighting in ("area", "uniform"):
        got = vertex_normals_torch(x, ft, weighting).numpy()
        assert got.dtype == np.float64 and got.shape == frames.shape
        assert np.abs(got - vertex_normals(frames, f, weighting)).max() < 1e-6
    assert np.abs(face_normals_torch(x, ft).numpy() - face_normals(frames, f)).max() < 1e-6
    assert vertex_normals_torch(x.float(), ft).dtype == torch.float32
    small = x[0, :12].clone().requires_grad_(True)
    fs = ft[(ft < 12).all(1)]
    assert torch.autograd.gradcheck(lambda v: vertex_normals_torch(v, fs), (small,))
    assert torch.autograd.gradcheck(lambda v: face_normals_torch(v, fs), (small,))
    flat = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], dtype=torch.float64, requires_grad=True)
    n = vertex_normals_torch(flat, torch.tensor([[0, 1, 2], [0, 1, 3]]))
    assert torch.equal(n[2], torch.zeros(3, dtype=torch.float64))  # only in the collinear face
    n.sum().backward()
    assert torch.isfinite(flat.grad).all()


def test_angle_weighted_normals_are_libigls_frame_by_frame():
    """:func:`angle_weighted_normals` over frames at once against libigl's angle-weighted vertex normals and its face
    normals, frame by frame, on a mesh with triangles of very different angles (a subdivided, jittered icosphere)."""
    import igl
    import trimesh

    from loosefit.geometry.normals import angle_weighted_normals

    sphere = trimesh.creation.icosphere(2)
    rng = np.random.default_rng(4)
    verts = sphere.vertices[None] * rng.uniform(0.5, 1.5, (3, 1, 3)) + rng.normal(0, 0.02, (3, len(sphere.vertices), 3))
    faces = np.asarray(sphere.faces, np.int64)
    fn, vn = angle_weighted_normals(verts, faces)
    for t in range(3):
        v = np.ascontiguousarray(verts[t])
        np.testing.assert_allclose(vn[t], igl.per_vertex_normals(v, faces, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_ANGLE),
                                   atol=1e-12)
        np.testing.assert_allclose(fn[t], igl.per_face_normals(v, faces, np.zeros(3)), atol=1e-12)
