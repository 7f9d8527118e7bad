"""FitGar's equations against closed forms on a batch made here (two frames of a small sheet, random inputs;
no body, no store): the coarse graph reads the first fit factor only (Sec. 4.3), FitGar Eqs. 5 and 9 add the
displacements, FitGar Eq. 7 gates the first detail block by the parser's encoding, and each loss is the mean
squared displacement error in units of its output scale squared."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.models.fitgar import FitGar
from loosefit.models.fitgar_data import collate_frames
from loosefit.models.fitgar_inputs import graph_edges
from tests.rig.conftest import sheet

from .fitgar_fixtures import TINY

J, S, F = 4, 3, 4
SIZES = {"num_joints": J, "num_shape": S, "num_fit_factors": F, "pose_features": 6 * J, "fit_length": 8}


def frames(count: int = 2, seed: int = 0) -> list[dict]:
    """``count`` frames of a 4 x 3 sheet with random inputs and targets (metres)."""
    verts, faces = sheet(4, 3, width=0.3, height=0.2)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        anchor = verts + rng.normal(0, 0.01, verts.shape)
        normal = rng.normal(size=verts.shape)
        out.append({"anchor": anchor, "body_normal": normal / np.linalg.norm(normal, axis=1, keepdims=True),
                    "body_rel": rng.normal(0, 0.1, verts.shape), "garment_rel": rng.normal(0, 0.1, verts.shape),
                    "joints": rng.normal(0, 0.3, (J, 3)), "pose": rng.normal(0, 0.5, 6 * J),
                    "shape": rng.normal(size=S), "alpha": rng.normal(size=F), "edges": graph_edges(faces),
                    "faces": faces, "smooth": anchor + rng.normal(0, 0.02, verts.shape),
                    "verts": anchor + rng.normal(0, 0.03, verts.shape)})
    return out


@pytest.fixture
def model() -> FitGar:
    torch.manual_seed(0)
    model = FitGar(SIZES, TINY)
    with torch.no_grad():
        model.coarse.output.scale.fill_(0.02)
        model.detail.output.scale.fill_(0.005)
    return model


def test_coarse_graph_reads_the_first_fit_factor_only(model):
    """FitGar Sec. 4.3: the coarse node features are ``[n_b, p_b, a_1]``, the first (most discriminative) factor
    of the fit attribute; the others reach the detail generator through the parser."""
    items = frames()
    base = model.coarse_displacement(collate_frames(items)).detach()
    for it in items:
        it["alpha"][1:] += 3.0
    torch.testing.assert_close(model.coarse_displacement(collate_frames(items)).detach(), base, rtol=0, atol=0)
    for it in items:
        it["alpha"][0] += 3.0
    assert (model.coarse_displacement(collate_frames(items)).detach() - base).abs().max() > 1e-5


def test_eqs_5_and_9_add_the_displacements(model):
    """``M_coarse = I M_b + Delta_coarse`` (FitGar Eq. 5) and ``M_detail = M_coarse + Delta_detail`` (Eq. 9)."""
    batch = collate_frames(frames())
    out = model(batch)
    torch.testing.assert_close(out["coarse"], batch["anchor"] + model.coarse_displacement(batch), rtol=0, atol=1e-7)
    torch.testing.assert_close(out["verts"], out["coarse"] + model.detail_displacement(batch, out["coarse"]),
                               rtol=0, atol=1e-7)
    assert out["detail_displacement"].abs().max() > 1e-5 and out["coarse_displacement"].abs().max() > 1e-5


def test_eq7_gates_the_first_block_by_the_encoding(model):
    """FitGar Eq. 7: ``G* = W_parser(alpha, beta, theta) o W_detail^[1](G)``. The parser ends in a ReLU, so its
    encoding is never negative (it can only gate, see benchmarks/README.md); an encoding of zeros shuts every
    feature, and the detail displacement no longer depends on the coarse mesh it reads."""
    batch = collate_frames(frames())
    assert isinstance(model.parser[-1], torch.nn.ReLU) and (model.encoding(batch) >= 0).all()
    coarse = batch["anchor"] + 0.01
    moved = coarse + torch.randn(coarse.shape, generator=torch.Generator().manual_seed(1)) * 0.05
    open_gate = [model.detail_displacement(batch, c).detach() for c in (coarse, moved)]
    assert (open_gate[0] - open_gate[1]).abs().max() > 1e-6
    with torch.no_grad():
        model.parser[-2].weight.zero_()
        model.parser[-2].bias.fill_(-1.0)  # ReLU(-1) = 0: a zero encoding
    shut = [model.detail_displacement(batch, c).detach() for c in (coarse, moved)]
    torch.testing.assert_close(shut[0], shut[1], rtol=0, atol=0)
    seen = []
    model.detail.magnitude.blocks[0].register_forward_hook(lambda m, args, out: seen.append(args[0].detach()))
    for value in (1.0, 2.5):
        with torch.no_grad():
            model.parser[-2].bias.fill_(value)  # a constant encoding: the first block's features times it
        model.detail_displacement(batch, coarse)
    torch.testing.assert_close(seen[1], 2.5 * seen[0], rtol=1e-6, atol=1e-7)
    assert seen[0].abs().max() > 0.1


def zero_magnitude(generator) -> None:
    """A generator whose magnitude branch outputs exactly 0 (ReLU of -1): a zero displacement."""
    with torch.no_grad():
        last = generator.output.magnitude[-2]
        last.weight.zero_()
        last.bias.fill_(-1.0)


def test_losses_are_in_units_of_the_output_scale_squared(model):
    """Each term is the mean squared displacement error over vertices and coordinates divided by its output
    scale squared: for a zero prediction, ``mean((smooth - anchor)^2) / s_c^2`` and ``mean((verts - coarse)^2) /
    s_d^2``, with the coarse mesh the (frozen) coarse generator's."""
    batch = collate_frames(frames())
    zero_magnitude(model.coarse)
    zero_magnitude(model.detail)
    coarse = model.loss_terms(batch, "coarse")["coarse"].detach()
    expected = ((batch["smooth"] - batch["anchor"]) ** 2).mean() / 0.02**2
    assert float(coarse) == pytest.approx(float(expected), rel=1e-6)
    detail = model.loss_terms(batch, "detail")["detail"].detach()
    expected = ((batch["verts"] - batch["anchor"]) ** 2).mean() / 0.005**2  # the coarse mesh is the anchor
    assert float(detail) == pytest.approx(float(expected), rel=1e-6)
    loss, _ = model.training_loss(batch, "coarse")
    assert float(loss.detach()) == pytest.approx(float(coarse), rel=1e-12)  # coarse_weight 1


def test_paper_sizes():
    """FitGar Sec. 5.1: GAT blocks of 4 heads, the coarse generator's first block 256 wide (128 self, 4 x 32),
    branches [512, 512, 256] then [256, 128]; the parser [256, 512, 1024]; the detail generator's first block
    1024, then [256, 256, 128, 96] and [128, 64]; the direct-output ablation's limit factor 5."""
    from loosefit.models.fitgar import FitGarConfig

    c = FitGarConfig()
    assert (c.heads, c.coarse_first, c.coarse_blocks, c.coarse_dense) == (4, 256, (512, 512, 256), (256, 128))
    assert (c.parser, c.detail_first, c.detail_blocks, c.detail_dense) == ((256, 512, 1024), 1024,
                                                                          (256, 256, 128, 96), (128, 64))
    assert c.limit_factor == 5.0 and c.self_fraction == 0.5
