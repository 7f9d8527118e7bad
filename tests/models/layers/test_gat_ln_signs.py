"""GAT-LN's constants against SwinGar Eq. 4 written out by hand on a five-vertex graph: the score scale
``alpha``, the larger of the two norms as the normaliser, GAT's LeakyReLU slope 0.2, the softmax over each
neighbourhood, heads averaged, the bias and tanh; and two closed forms (``alpha = 0`` is a neighbourhood mean,
equal heads average to one head)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from loosefit.models.layers.gat_ln import GATLN, attention_table

FACES = np.array([[0, 1, 2], [1, 3, 2], [3, 4, 2]])
V, IN, OUT = 5, 3, 4


def graph():
    return map(torch.from_numpy, attention_table(FACES, V))


def neighbourhoods() -> list[list[int]]:
    """Each vertex and its mesh neighbours, by hand from ``FACES``."""
    near = {i: {i} for i in range(V)}
    for f in FACES:
        for a in f:
            near[int(a)].update(int(b) for b in f)
    return [sorted(near[i]) for i in range(V)]


def by_hand(layer: GATLN, x: torch.Tensor, alpha: float | None, slope: float = 0.2) -> torch.Tensor:
    """SwinGar Eq. 2 and 4 for one graph ``x (V, in)``, loop by loop, float64."""
    H, C = layer.heads, layer.out_channels
    W = layer.weight.detach().double().view(IN, H, C)
    near = neighbourhoods()
    out = torch.zeros(V, C, dtype=torch.float64)
    for h in range(H):
        Wx = x @ W[:, h]  # (V, C)
        a_dst, a_src = layer.att_dst[h].detach().double(), layer.att_src[h].detach().double()
        s = {(i, j): float(a_dst @ Wx[i] + a_src @ Wx[j]) for i in range(V) for j in near[i]}
        if alpha is not None:
            row = max(math.sqrt(sum(s[i, j] ** 2 for j in near[i])) for i in range(V))  # (2, inf)-norm
            c_dst, c_src = W[:, h] @ a_dst, W[:, h] @ a_src  # the score function on x: c_dst . x_i + c_src . x_j
            lip = float(torch.cat([c_dst, c_src]).norm())  # its spectral norm (a row vector's length)
            feat = float(x.norm(dim=1).max())  # (inf, 2)-norm of the features
            s = {k: alpha * v / max(row, feat * lip) for k, v in s.items()}
        for i in range(V):
            e = [math.exp(v if v > 0 else slope * v) for v in (s[i, j] for j in near[i])]
            for j, ej in zip(near[i], e):
                out[i] += ej / sum(e) * Wx[j] / H  # heads averaged
    return torch.tanh(out + layer.bias.detach().double())


@pytest.mark.parametrize("alpha, heads", [(2.0, 1), (2.0, 3), (0.7, 2), (None, 2)])
def test_layer_is_eq4_by_hand(alpha, heads):
    torch.manual_seed(0)
    layer = GATLN(IN, OUT, heads=heads, alpha=alpha)
    with torch.no_grad():
        layer.bias.normal_()  # it starts at zero
        layer.att_src.mul_(3.0)  # scores on both sides of zero, some large
    table, valid = graph()
    x = torch.randn(V, IN, generator=torch.Generator().manual_seed(1), dtype=torch.float64) * 2.0
    got = layer.double()(x, table, valid)
    torch.testing.assert_close(got, by_hand(layer, x, alpha), rtol=1e-10, atol=1e-12)


def test_the_normaliser_is_the_larger_of_the_two_norms():
    """Two graphs, one for each side of the ``max`` of SwinGar Eq. 4 (one head): features all along the score
    vectors make the score rows long (``||g||_(2,inf)`` wins); one long feature orthogonal to both score vectors
    makes ``||X||_(inf,2) L(g)`` win while adding nothing to any score. Each time the attention is the softmax of
    ``LeakyReLU_0.2(alpha s / normaliser)`` with the larger norm as the normaliser."""
    torch.manual_seed(2)
    layer = GATLN(IN, OUT, heads=1, alpha=2.0).double()
    table, valid = graph()
    c_dst, c_src = (c[0].detach() for c in layer.score_vectors())
    lip = float(torch.cat([c_dst, c_src]).norm())
    along = (c_dst + c_src) / (c_dst + c_src).norm()
    across = torch.linalg.cross(c_dst, c_src)
    rows = torch.linspace(0.5, 1.0, V, dtype=torch.float64)[:, None]
    long_rows = rows * along
    long_feature = torch.cat([0.01 * rows[:-1] * along, 100.0 * (across / across.norm())[None]])
    for x, row_wins in ((long_rows, True), (long_feature, False)):
        s = (x @ c_dst)[:, None] + (x @ c_src)[table]  # (V, D)
        s = s * valid
        row = float(s.square().sum(1).sqrt().max())
        feat = float(x.norm(dim=1).max()) * lip
        assert (row > feat) == row_wins
        g = 2.0 * s / max(row, feat)
        g = torch.where(g > 0, g, 0.2 * g).masked_fill(~valid, float("-inf"))
        got = layer.attention(x[None], table, valid)[0, :, :, 0]
        torch.testing.assert_close(got, torch.softmax(g, 1), rtol=1e-10, atol=1e-12)


def test_alpha_zero_is_the_neighbourhood_mean():
    """``alpha = 0``: every score is 0 and the attention is uniform: ``tanh(mean_{j in N(i) + i} W x_j + b)``."""
    torch.manual_seed(3)
    layer = GATLN(IN, OUT, heads=2, alpha=0.0).double()
    with torch.no_grad():
        layer.bias.normal_()
    table, valid = graph()
    x = torch.randn(V, IN, dtype=torch.float64)
    W = layer.weight.detach().view(IN, 2, OUT).mean(1)  # the heads' average projection
    expected = torch.stack([x[n].mean(0) @ W for n in neighbourhoods()]) + layer.bias.detach()
    torch.testing.assert_close(layer(x, table, valid), torch.tanh(expected), rtol=1e-10, atol=1e-12)


def test_equal_heads_average_to_one_head():
    """Heads are averaged (not summed, not concatenated): three copies of one head give that head's output."""
    torch.manual_seed(4)
    one = GATLN(IN, OUT, heads=1, alpha=2.0, activation=None).double()
    three = GATLN(IN, OUT, heads=3, alpha=2.0, activation=None).double()
    with torch.no_grad():
        three.weight.copy_(one.weight.repeat(1, 3))
        three.att_dst.copy_(one.att_dst.repeat(3, 1))
        three.att_src.copy_(one.att_src.repeat(3, 1))
        one.bias.normal_()
        three.bias.copy_(one.bias)
    table, valid = graph()
    x = torch.randn(2, V, IN, dtype=torch.float64)
    torch.testing.assert_close(three(x, table, valid), one(x, table, valid), rtol=1e-10, atol=1e-12)
