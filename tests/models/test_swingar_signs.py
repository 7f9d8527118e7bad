"""SwinGar's loss terms (SwinGar Eqs. 11-14) against tiny hand-computed cases: the sign of gravity, the
Laplacian of the face normals, the direction of the collision margin, squared (not plain) distances, and the
paper's constants. No data store: the terms are computed on meshes of a few triangles."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.geometry.laplacian import edges
from loosefit.models.multi_garment import face_pairs
from loosefit.models.swingar import GRAVITY, SwinGar, SwinGarConfig

TINY = SwinGarConfig(graph_hidden=[4, 8], graph_heads=[1, 1], shape_mlp=[8, 4], motion_hidden=8, motion_frames=2,
                     body_mlp=[8, 4], state_hidden=4, state_heads=1, blend_hidden=[4, 8], blend_heads=1,
                     corrective_hidden=4, corrective_heads=1, corrective_layers=[4, 3], descriptor_samples=4,
                     global_descriptor="none")
#: A strip of three triangles: faces 0 and 1 share the edge (1, 2), faces 1 and 2 the edge (2, 3).
STRIP = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4]])
FLAT = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 2.0, 0.0]])


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return SwinGar({"num_joints": 3, "parents": [-1, 0, 1], "shape_values": 2}, TINY).double()


def batch_of(target: np.ndarray, faces: np.ndarray = STRIP, mass=None, **extra) -> dict:
    """A batch of one window of ``target (T, V, 3)``."""
    g = {"faces": torch.from_numpy(faces), "edges": torch.from_numpy(edges(faces)),
         "face_pairs": torch.from_numpy(face_pairs(faces)),
         "mass": torch.ones(target.shape[1], dtype=torch.float64) if mass is None else torch.as_tensor(mass)}
    return {"graph_tensors": g, "verts": torch.as_tensor(target)[None], **extra}


def test_gravity_charges_raising_a_vertex_and_pays_for_lowering_it(model):
    """SwinGar Eq. 13, ``-k_g M X g`` with ``g = (0, 0, -9.8)``: potential energy ``9.8 m z``. The term is that
    energy above the simulation's: ``9.8 m_i h`` for vertex ``i`` raised by ``h``, negative when lowered, and its
    gradient ``9.8 m`` along +z, so that descent lowers the garment."""
    target = FLAT[None].repeat(2, 0)
    mass = torch.tensor([0.01, 0.02, 0.03, 0.04, 0.05], dtype=torch.float64)
    b = batch_of(target, mass=mass)
    assert GRAVITY == 9.8
    for h in (0.01, -0.02):
        pred = torch.from_numpy(target.copy())[None]
        pred[..., 3, 2] += h  # vertex 3 raised (lowered) by h in both frames
        assert float(model.loss_terms(pred, b)["gravity"]) == pytest.approx(9.8 * 0.04 * h, rel=1e-12)
    pred = torch.from_numpy(target.copy())[None].requires_grad_(True)
    model.loss_terms(pred, b)["gravity"].backward()
    expected = torch.zeros_like(pred)
    expected[..., 2] = 9.8 * mass / 2  # averaged over the 2 frames
    torch.testing.assert_close(pred.grad, expected, rtol=1e-12, atol=1e-15)
    shifted = pred.detach().clone()
    shifted[..., 0:2] += 0.3  # sideways moves cost nothing
    assert float(model.loss_terms(shifted, b)["gravity"]) == 0.0


def test_vertex_term_is_the_mean_squared_distance(model):
    """SwinGar Eq. 11: ``mean_i |X_i - X_i^GT|^2`` (squared, summed over x, y, z, averaged over vertices)."""
    target = FLAT[None]
    pred = torch.from_numpy(target.copy())[None]
    pred[..., 1, :] += torch.tensor([0.03, -0.04, 0.0], dtype=torch.float64)  # 5 cm off
    assert float(model.loss_terms(pred, batch_of(target))["vert"]) == pytest.approx(0.05**2 / 5, rel=1e-12)


def test_edge_term_is_the_mean_squared_length_change(model):
    """SwinGar Eq. 12's first term: ``mean_e (|e| - |e^GT|)^2`` over the mesh edges: stretching the strip along y
    by a factor ``s`` changes the length of edge ``e`` by ``(s - 1) |e_y|`` only for edges along y; the
    diagonals by ``|s e| - |e|``."""
    target = FLAT[None]
    s = 1.1
    pred = torch.from_numpy(target.copy())[None]
    pred[..., 1] *= s
    e = edges(STRIP)
    d = FLAT[e[:, 0]] - FLAT[e[:, 1]]
    change = np.linalg.norm(d * [1.0, s, 1.0], axis=1) - np.linalg.norm(d, axis=1)
    assert len(e) == 7
    assert float(model.loss_terms(pred, batch_of(target))["edge"]) == pytest.approx(np.mean(change**2), rel=1e-12)


def face_normal(p: np.ndarray, f) -> np.ndarray:
    n = np.cross(p[f[1]] - p[f[0]], p[f[2]] - p[f[0]])
    return n / np.linalg.norm(n)


def test_bending_term_is_the_laplacian_of_the_face_normals(model):
    """SwinGar Eq. 12's second term, ``|Delta(N)|^2``: the graph Laplacian of the face adjacency on the face
    normals, ``(L N)_f = sum_{g ~ f} (n_g - n_f)``, squared and averaged over faces. Here the strip is folded
    along both shared edges; the middle face has two neighbours, the end faces one, and the end faces do not
    touch (they share only a vertex). A flat strip costs nothing."""
    assert face_pairs(STRIP).tolist() == [[0, 1], [1, 2]]
    folded = FLAT.copy()
    folded[0, 2], folded[4, 2] = 0.4, -0.7  # raise one end and lower the other
    n = np.stack([face_normal(folded, f) for f in STRIP])
    lap = np.stack([n[1] - n[0], (n[0] - n[1]) + (n[2] - n[1]), n[1] - n[2]])
    expected = np.mean(np.sum(lap**2, 1))
    b = batch_of(FLAT[None])
    got = float(model.loss_terms(torch.from_numpy(folded)[None, None], b)["bend"])
    assert got == pytest.approx(expected, rel=1e-12)
    assert expected > 0.1
    assert float(model.loss_terms(torch.from_numpy(FLAT)[None, None] * 2.0, b)["bend"]) == 0.0


def test_collision_margin_keeps_vertices_eps_outside(model):
    """SwinGar Eq. 14, ``k_c |min(h - eps, 0)|^2`` with ``h`` the signed distance along the body normal (positive
    outside): a vertex ``eps`` or more outside costs nothing, one closer costs ``(eps - h)^2`` and one inside more.
    Body: the plane z = 0, normal +z."""
    eps = TINY.collision_eps
    assert eps == 0.002  # metres
    heights = np.array([-eps, 0.0, 0.5 * eps, eps, 3 * eps])
    pred = np.zeros((1, 1, 5, 3))
    pred[..., 2] = heights
    body = torch.zeros(1, 1, 1, 3, dtype=torch.float64)
    normals = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand(1, 1, 1, 3)
    b = batch_of(np.zeros((1, 5, 3)), body=body, body_normals=normals,
                 body_nearest=torch.zeros(1, 1, 5, dtype=torch.long))
    expected = np.mean(np.minimum(heights - eps, 0.0) ** 2)  # (2 eps)^2, eps^2, (eps / 2)^2, 0, 0
    assert expected == pytest.approx((4 + 1 + 0.25) * eps**2 / 5, rel=1e-12)
    assert float(model.loss_terms(torch.from_numpy(pred), b)["collision"]) == pytest.approx(expected, rel=1e-12)
    flipped = torch.from_numpy(pred).clone()
    flipped[..., 2] *= -1  # the body's normal the other way round: now the vertices above are inside
    b["body_normals"] = -normals
    assert float(model.loss_terms(flipped, b)["collision"]) == pytest.approx(expected, rel=1e-12)


def test_paper_constants():
    """SwinGar Sec. IV: ``k_v, k_e, k_b, k_g, k_c = 50, 10, 3, 0.2, 1.5``, ``alpha = 2``, tanh GAT-LN layers."""
    c = SwinGarConfig()
    assert (c.k_vert, c.k_edge, c.k_bend, c.k_gravity, c.k_collision) == (50.0, 10.0, 3.0, 0.2, 1.5)
    assert c.alpha == 2.0 and c.motion_frames == 64 and c.corrective_frames == 3
    model = SwinGar({"num_joints": 3, "parents": [-1, 0, 1], "shape_values": 2}, TINY)
    gat = [model.state_encoder, *model.graph_encoder, *model.blend_layers, *model.corrective_layers]
    assert all(layer.activation == "tanh" and layer.alpha == 2.0 for layer in gat)
