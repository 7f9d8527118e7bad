"""Output reconstruction (FitGar Sec. 4.2, FitGar Eq. 4) against its closed form."""

import math

import pytest
import torch

from loosefit.errors import InputError
from loosefit.models.layers.decomposed_output import DecomposedOutput, compose_displacement, unit_direction


def test_single_layers_match_the_closed_form():
    """One linear layer per branch: Delta = s * relu(w.x + b) * tanh(U y + c) / |tanh(U y + c)|."""
    head = DecomposedOutput(2, 2, hidden=(), scale=0.05)
    with torch.no_grad():
        head.magnitude[0].weight.copy_(torch.tensor([[1.0, -2.0]]))
        head.magnitude[0].bias.fill_(0.25)
        head.direction[0].weight.copy_(torch.tensor([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]))
        head.direction[0].bias.copy_(torch.tensor([0.0, 0.5, -0.5]))
    m = torch.tensor([[1.0, 0.25], [0.0, 1.0]])  # w.x + b = 0.75 and -1.75 (ReLU: 0)
    d = torch.tensor([[0.3, -0.2], [1.0, 1.0]])
    out = head(m, d)
    t = [math.tanh(0.3), math.tanh(0.3), math.tanh(0.3 - 0.2 - 0.5)]
    n = math.sqrt(sum(v * v for v in t))
    expected0 = [0.05 * 0.75 * v / n for v in t]
    torch.testing.assert_close(out["displacement"][0], torch.tensor(expected0), rtol=1e-6, atol=1e-8)
    assert torch.equal(out["displacement"][1], torch.zeros(3))  # zero magnitude, zero displacement
    torch.testing.assert_close(out["magnitude"][:, 0], torch.tensor([0.05 * 0.75, 0.0]))


def test_magnitude_is_the_length_and_never_negative():
    torch.manual_seed(0)
    head = DecomposedOutput(8, 6, hidden=(16, 8), scale=0.1)
    out = head(torch.randn(500, 8) * 3, torch.randn(500, 6) * 3)
    assert (out["magnitude"] >= 0).all()
    lengths = out["displacement"].norm(dim=-1)
    torch.testing.assert_close(lengths, out["magnitude"][:, 0], rtol=1e-5, atol=1e-7)
    nonzero = out["direction"].norm(dim=-1) > 0
    torch.testing.assert_close(out["direction"][nonzero].norm(dim=-1), torch.ones(int(nonzero.sum())))
    # each stack ends in its activation: the raw direction lies in [-1, 1]
    raw = head.direction(torch.randn(50, 6) * 10)
    assert raw.abs().max() <= 1.0
    # the last magnitude layer starts open (positive bias), so most vertices get a gradient at once
    assert (out["magnitude"] > 0).float().mean() > 0.5


def test_compose_and_unit_direction():
    assert torch.equal(compose_displacement(torch.tensor([[2.0]]), torch.tensor([[0.0, 1.0, 0.0]])),
                       torch.tensor([[0.0, 2.0, 0.0]]))
    torch.testing.assert_close(unit_direction(torch.tensor([[3.0, 0.0, 4.0]])), torch.tensor([[0.6, 0.0, 0.8]]))
    assert torch.equal(unit_direction(torch.zeros(1, 3)), torch.zeros(1, 3))


def test_bad_stack():
    from loosefit.models.layers.mlp import MLP

    with pytest.raises(InputError):
        MLP((4,), torch.nn.ReLU)
