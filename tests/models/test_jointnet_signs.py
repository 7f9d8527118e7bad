"""JointNet's constants against closed forms on a model built from sizes alone (no data store): the Fourier
frequencies' scale and the ``2 pi`` of JointNet Eq. 3, the garment prior concatenated with the bone features
(JointNet Fig. 2; Eq. 4's sum as an option), the association's and the PSD bases' initial scales, and the
per-coordinate L1 of JointNet Eq. 7."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from loosefit.models.jointnet import PSD_INIT_STD, JointNet, JointNetConfig
from loosefit.train.losses import vertex_l1

TINY = JointNetConfig(gru_hidden=8, features=16, bone_mlp=[16], psd_mlp=[8, 8], psd_shapes=4)
NAMES = ["root", "spine", "neck", "arm_l", "arm_r"]
PARENTS = [-1, 0, 1, 1, 1]


def build(config: JointNetConfig = TINY, bones: int = 6, verts: int = 10, seed: int = 0) -> JointNet:
    torch.manual_seed(seed)
    sizes = {"num_verts": verts, "num_joints": len(NAMES), "num_faces": 4, "num_bones": bones,
             "joint_names": NAMES, "parents": PARENTS}
    return JointNet(sizes, config)


def test_fourier_frequencies_have_the_configured_scale():
    """``c_m`` are normal with standard deviation ``fourier_scale`` cycles per metre: the same draw scaled."""
    assert JointNetConfig().fourier_scale == 2.0
    one = build(dataclasses.replace(TINY, fourier_scale=1.0))
    three = build(dataclasses.replace(TINY, fourier_scale=3.0))
    torch.testing.assert_close(three.fourier_freqs, 3.0 * one.fourier_freqs, rtol=1e-6, atol=0)
    wide = build(dataclasses.replace(TINY, features=2000, fourier_scale=2.0))  # 1000 frequencies, 3000 values
    assert wide.fourier_freqs.shape == (1000, 3)
    assert float(wide.fourier_freqs.std()) == pytest.approx(2.0, rel=0.06)  # 4 standard errors


def test_fourier_feature_at_the_paper_frequency():
    """JointNet Eq. 3: ``[alpha cos(2 pi c . p), alpha sin(2 pi c . p)]``: ``c . p = 1/8`` gives ``alpha / sqrt 2``
    twice, ``c . p = 1`` a whole period (``alpha``, 0), ``c . p = 1/4`` a quarter (0, ``alpha``)."""
    model = build(dataclasses.replace(TINY, features=6), bones=3)
    with torch.no_grad():
        model.fourier_freqs.copy_(torch.tensor([[0.5, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]))
        model.fourier_alpha.copy_(torch.tensor([1.0, 2.0, 3.0]))
        model.bone_rest.copy_(torch.tensor([[0.25, 0.0625, 0.125], [2.0, 0.5, 0.25], [0.0, 0.0, 0.0]]))
    r = math.sqrt(0.5)
    # bone 0: c . p = 1/8, 1/8, 1/8; bone 1: 1, 1, 1/4; bone 2: 0
    expected = torch.tensor([[r, 2 * r, 3 * r, r, 2 * r, 3 * r],
                             [1.0, 2.0, 0.0, 0.0, 0.0, 3.0],
                             [1.0, 2.0, 3.0, 0.0, 0.0, 0.0]])
    torch.testing.assert_close(model.fourier_features().detach(), expected, rtol=0, atol=1e-6)


def test_garment_prior_is_concatenated_with_the_bone_features():
    """The paper's Fig. 2 and Sec. 3.2 concatenate ``f_V`` with ``relu(A) psi`` (the default): with no joint
    associated, the bone MLP reads ``K`` zeros then the Fourier features, ``2 K`` wide; ``fourier="add"``
    (Eq. 4's sum) reads the Fourier features alone, ``K`` wide."""
    for mode, width in (("concat", 2 * TINY.features), ("add", TINY.features)):
        model = build(dataclasses.replace(TINY, fourier=mode))
        assert model.bone_mlp[0].in_features == width
        seen = []
        model.bone_mlp.register_forward_hook(lambda module, args, out: seen.append(args[0].detach()))
        with torch.no_grad():
            model.association.fill_(-1.0)  # relu(A) = 0
            model(torch.randn(2, 3, 11), torch.randn(2, 3, len(NAMES) - 1, 6), psd=False)
        prior = model.fourier_features().detach().expand(2, 3, -1, -1)
        expected = torch.cat([torch.zeros_like(prior), prior], -1) if mode == "concat" else prior
        assert seen[0].shape == (2, 3, 6, width)
        torch.testing.assert_close(seen[0], expected, rtol=0, atol=0)
    assert JointNetConfig().fourier == "concat"


def test_association_starts_with_rows_summing_to_one():
    """``A`` starts uniform in ``[0, 2 / J_s)``: a bone starts from about the mean of the joint features (row sums
    1 on average, standard deviation ``1 / sqrt(3 J_s)`` per row)."""
    model = build(bones=400)
    A = model.association.detach()
    assert A.shape == (400, 4) and A.min() >= 0 and A.max() < 0.5
    assert float(A.sum(1).mean()) == pytest.approx(1.0, abs=0.05)  # 400 rows: standard error 0.014


def test_psd_bases_start_small_but_not_zero():
    """``D_j`` start normal with standard deviation ``PSD_INIT_STD`` (1e-5 m): the skinned garment barely moves,
    and the PSD weight MLP ``phi`` gets a gradient from the first step."""
    assert PSD_INIT_STD == 1e-5
    model = build(dataclasses.replace(TINY, psd_shapes=16), verts=200)
    assert float(model.psd_basis.detach().std()) == pytest.approx(1e-5, rel=0.05)  # 38,400 values
    out = model(torch.randn(1, 2, 11), torch.randn(1, 2, len(NAMES) - 1, 6))
    out["displacement"].square().sum().backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in model.psd_mlp.parameters())


def test_cloth_loss_is_the_mean_absolute_coordinate_error():
    """JointNet Eq. 7's L1 averaged per coordinate (the paper sums over the mesh; loosefit averages, so that
    ``lambda_norm`` and ``lambda_s`` do not depend on the vertex count): one coordinate off by ``d`` in ``V``
    vertices over ``T`` frames costs ``d / (3 V)``."""
    target = torch.zeros(1, 4, 5, 3)
    pred = target.clone()
    pred[0, :, 2, 1] = -0.03
    assert float(vertex_l1(pred, target)) == pytest.approx(0.03 / 15, rel=1e-6)
    c = JointNetConfig()
    assert (c.lambda_norm, c.lambda_sparse, c.association, c.association_radius) == (0.05, 1e-4, "hoyer", 0.4)
