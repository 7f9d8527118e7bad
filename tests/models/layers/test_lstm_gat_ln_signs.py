"""LSTM-GAT-LN's gates against SwinGar Eq. 6 written out by hand: every peephole on its own gate and on the
previous cell, torch's gate order (i, f, g, o), and what a closed or open gate does to the cell.

On a graph without edges every node attends only to itself, so with one head each GAT-LN map is the affine map
``x W + b`` and the cell's update can be computed by hand from its parameters."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.models.layers.gat_ln import attention_table
from loosefit.models.layers.lstm_gat_ln import LSTMGATLN

V, IN, HID = 6, 4, 5


def self_only():
    return map(torch.from_numpy, attention_table(np.zeros((0, 3), np.int64), V))


def affine(layer, x):
    """A one-head GAT-LN on self-only attention: ``x W + b`` (no activation in the LSTM's maps)."""
    return x @ layer.weight + layer.bias


@pytest.fixture
def cell():
    torch.manual_seed(0)
    cell = LSTMGATLN(IN, HID, heads=1, alpha=2.0).double()
    with torch.no_grad():
        # distinct peepholes (they start at zero): a gate reading another gate's weight gives other numbers
        cell.peephole.copy_(torch.tensor([0.9, -1.3, 0.6], dtype=torch.float64)[:, None]
                            * torch.linspace(0.5, 1.5, HID, dtype=torch.float64))
    return cell


def test_one_step_is_eq6_by_hand(cell):
    """``i, f, o = sigma(A(x) + S(H) + w o C^{t-1})`` each with its own ``w``; ``C^t = i tanh(g) + f C^{t-1}``;
    ``H^t = o tanh(C^t)``."""
    table, valid = self_only()
    g = torch.Generator().manual_seed(1)
    x, h, c = (torch.randn(V, n, generator=g, dtype=torch.float64) for n in (IN, HID, HID))
    c = 2.0 * c  # a cell well away from zero: the peepholes matter
    gates = affine(cell.input_map, x) + affine(cell.state_map, h)
    a_i, a_f, a_g, a_o = gates.chunk(4, -1)
    w_i, w_f, w_o = cell.peephole
    i = torch.sigmoid(a_i + w_i * c)
    f = torch.sigmoid(a_f + w_f * c)
    o = torch.sigmoid(a_o + w_o * c)
    c_new = i * torch.tanh(a_g) + f * c
    h_new = o * torch.tanh(c_new)
    H, C = cell.cell(x, table, valid, (h, c))
    torch.testing.assert_close(C, c_new, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(H, h_new, rtol=1e-12, atol=1e-12)
    # the sequence loop runs the same cell
    out, (H2, C2) = cell(x[None], table, valid, (h, c))
    torch.testing.assert_close(out[0], h_new, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(C2, c_new, rtol=1e-12, atol=1e-12)


def test_each_peephole_moves_only_its_own_gate(cell):
    """Raising ``w_f`` changes the cell through the forget gate alone: with the input gate shut and the output
    gate fully open, ``C^t = f C^{t-1}`` and ``H^t = tanh(C^t)``; raising ``w_i`` or ``w_o`` then changes nothing."""
    table, valid = self_only()
    g = torch.Generator().manual_seed(2)
    x, h = torch.randn(V, IN, generator=g, dtype=torch.float64), torch.randn(V, HID, generator=g, dtype=torch.float64)
    c = torch.full((V, HID), 0.8, dtype=torch.float64)
    with torch.no_grad():
        cell.input_map.weight.zero_()
        cell.state_map.weight.zero_()
        cell.input_map.bias.zero_()
        bias = torch.zeros(4, HID, dtype=torch.float64)
        bias[0], bias[3] = -60.0, 60.0  # input gate shut, output gate open (torch order i, f, g, o)
        cell.state_map.bias.copy_(bias.flatten())
        cell.peephole.zero_()
        cell.peephole[1].fill_(1.5)
    H, C = cell.cell(x, table, valid, (h, c))
    forget = torch.sigmoid(torch.tensor(1.5 * 0.8, dtype=torch.float64))  # sigma(0 + w_f C^{t-1})
    torch.testing.assert_close(C, forget * c, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(H, torch.tanh(forget * c), rtol=1e-12, atol=1e-12)
    with torch.no_grad():
        cell.peephole[0].fill_(-3.0)
        cell.peephole[2].fill_(-3.0)  # an output gate at 60 - 2.4 is still open
    H2, C2 = cell.cell(x, table, valid, (h, c))
    torch.testing.assert_close(C2, C, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(H2, H, rtol=1e-10, atol=1e-12)


def test_a_closed_forget_gate_erases_the_cell_and_an_open_one_keeps_it(cell):
    """Forget gate 0: ``C^t = i tanh(g)`` whatever ``C^{t-1}`` was. Forget gate 1 and input gate 0:
    ``C^t = C^{t-1}``. Output gate 0: ``H^t = 0``."""
    table, valid = self_only()
    g = torch.Generator().manual_seed(3)
    x, h = torch.randn(V, IN, generator=g, dtype=torch.float64), torch.randn(V, HID, generator=g, dtype=torch.float64)
    c1, c2 = (torch.randn(V, HID, generator=g, dtype=torch.float64) for _ in range(2))
    with torch.no_grad():
        cell.peephole.zero_()
        bias = cell.state_map.bias.view(4, HID)
        bias[1] = -80.0  # forget gate shut
    (_, C1), (_, C2) = cell.cell(x, table, valid, (h, c1)), cell.cell(x, table, valid, (h, c2))
    torch.testing.assert_close(C1, C2, rtol=0, atol=1e-30)  # nothing of the old cell is left
    a_i, _, a_g, _ = (affine(cell.input_map, x) + affine(cell.state_map, h)).chunk(4, -1)
    torch.testing.assert_close(C1, torch.sigmoid(a_i) * torch.tanh(a_g), rtol=1e-12, atol=1e-12)
    with torch.no_grad():
        bias[1], bias[0] = 80.0, -80.0  # forget gate open, input gate shut: the cell carries over
    torch.testing.assert_close(cell.cell(x, table, valid, (h, c1))[1], c1, rtol=1e-12, atol=1e-12)
    with torch.no_grad():
        bias[3] = -80.0  # output gate shut
    assert cell.cell(x, table, valid, (h, c1))[0].abs().max() < 1e-30


def test_peepholes_read_the_previous_cell_not_the_new_one(cell):
    """SwinGar Eq. 6 puts ``C^{t-1}`` in all three gates (Graves's output gate reads ``C^t`` instead): with the
    previous cell zero, the peepholes change nothing, whatever the new cell is."""
    table, valid = self_only()
    g = torch.Generator().manual_seed(4)
    x, h = torch.randn(V, IN, generator=g, dtype=torch.float64), torch.randn(V, HID, generator=g, dtype=torch.float64)
    zero = torch.zeros(V, HID, dtype=torch.float64)
    H, C = cell.cell(x, table, valid, (h, zero))
    assert C.abs().max() > 0.05
    with torch.no_grad():
        cell.peephole.zero_()
    H0, C0 = cell.cell(x, table, valid, (h, zero))
    torch.testing.assert_close(H, H0, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(C, C0, rtol=1e-12, atol=1e-12)
