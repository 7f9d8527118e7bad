"""LSTM-GAT-LN (SwinGar Eq. 6): per-node LSTMCell when every node attends to itself; graph coupling otherwise."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.models.layers.gat_ln import attention_table
from loosefit.models.layers.lstm_gat_ln import LSTMGATLN
from tests.rig.conftest import tube

V, IN, HID = 40, 5, 7


def self_only():
    """Attention tables of a graph without edges: each node attends to itself (identity attention)."""
    return map(torch.from_numpy, attention_table(np.zeros((0, 3), np.int64), V))


def copy_lstm(cell: LSTMGATLN, ref: torch.nn.LSTMCell) -> None:
    with torch.no_grad():
        cell.input_map.weight.copy_(ref.weight_ih.T)
        cell.input_map.bias.copy_(ref.bias_ih)
        cell.state_map.weight.copy_(ref.weight_hh.T)
        cell.state_map.bias.copy_(ref.bias_hh)


@pytest.mark.parametrize("design", [{}, {"per_gate": True, "concat": True, "norm": "node", "centred": True}])
def test_identity_attention_equals_lstm_cell(design):
    """Shared or one GAT-LN per gate (SwinGar Eq. 6), one head each: the same weight layout as LSTMCell's."""
    torch.manual_seed(0)
    table, valid = self_only()
    ref = torch.nn.LSTMCell(IN, HID)
    cell = LSTMGATLN(IN, HID, heads=1, alpha=2.0, **design)
    copy_lstm(cell, ref)
    x = torch.randn(2, 6, V, IN)  # (B, T, V, in)
    out, (h, c) = cell(x, table, valid)
    assert out.shape == (2, 6, V, HID)
    hr = cr = torch.zeros(2 * V, HID)
    for t in range(6):
        hr, cr = ref(x[:, t].reshape(-1, IN), (hr, cr))
        torch.testing.assert_close(out[:, t].reshape(-1, HID), hr, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(c.reshape(-1, HID), cr, rtol=1e-5, atol=1e-6)
    # the peepholes of SwinGar Eq. 6 (zero at the start) are a departure from LSTMCell once trained
    with torch.no_grad():
        cell.peephole.fill_(0.5)
    assert (cell(x, table, valid)[0][:, 1:] - out[:, 1:]).abs().max() > 1e-3


def test_graph_couples_nodes_and_steps_equal_sequence():
    verts, faces = tube(5, 8)
    table, valid = map(torch.from_numpy, attention_table(faces, len(verts)))
    torch.manual_seed(1)
    cell = LSTMGATLN(IN, HID, heads=3)
    x = torch.randn(4, len(verts), IN)
    out, _ = cell(x, table, valid)
    state = None
    for t in range(4):  # streaming: one frame at a time, the state passed along
        state = cell.cell(x[t], table, valid, state)
        torch.testing.assert_close(state[0], out[t], rtol=1e-5, atol=1e-6)
    # a change at one node reaches its neighbours through the attention
    x2 = x.clone()
    x2[:, 0] += 1.0
    out2, _ = cell(x2, table, valid)
    neighbour = int(table[0, 1])
    assert (out2[0, neighbour] - out[0, neighbour]).abs().max() > 1e-4
    with pytest.raises(InputError):
        cell(x[0, 0], table, valid)


def test_per_gate_maps_give_each_gate_its_own_attention():
    """``per_gate``: the input map is four GAT-LN layers side by side, one per gate (SwinGar Eq. 6): changing
    the attention vectors of the forget gate's heads moves the forget gate's pre-activations only."""
    verts, faces = tube(5, 8)
    table, valid = map(torch.from_numpy, attention_table(faces, len(verts)))
    torch.manual_seed(4)
    cell = LSTMGATLN(IN, HID, heads=2, per_gate=True, concat=True, norm="node", centred=True)
    assert cell.input_map.heads == 8 and cell.input_map.groups == 4
    x = torch.randn(len(verts), IN)
    with torch.no_grad():
        before = cell.input_map(x, table, valid)
        cell.input_map.att_src[HID:2 * HID] += 1.0  # the forget gate's block (torch's order i, f, g, o)
        after = cell.input_map(x, table, valid)
    moved = (after - before).abs().amax(0)
    assert moved[HID:2 * HID].max() > 1e-4 and moved[:HID].max() == 0 and moved[2 * HID:].max() == 0
    with pytest.raises(InputError, match="concatenated"):
        LSTMGATLN(IN, HID, heads=2, per_gate=True)


def test_gradients_are_finite_from_a_zero_state():
    """The first step's state-to-state map sees zeros: its norms must not give NaN gradients."""
    verts, faces = tube(5, 8)
    table, valid = map(torch.from_numpy, attention_table(faces, len(verts)))
    torch.manual_seed(2)
    cell = LSTMGATLN(IN, HID, heads=2)
    out, _ = cell(torch.randn(3, len(verts), IN), table, valid)
    out.sum().backward()
    for name, p in cell.named_parameters():
        assert torch.isfinite(p.grad).all() and p.grad.abs().sum() > 0, name


def test_a_step_from_no_state_equals_a_step_from_explicit_zeros():
    """From no state the cell skips its state map (zeros map to its bias): the same ``(H, C)`` as the full
    step on explicit zeros, whose gradients stay finite."""
    verts, faces = tube(5, 8)
    table, valid = map(torch.from_numpy, attention_table(faces, len(verts)))
    torch.manual_seed(3)
    cell = LSTMGATLN(IN, HID, heads=2)
    with torch.no_grad():
        cell.peephole.normal_()
        cell.state_map.bias.normal_()
    x = torch.randn(2, len(verts), IN)
    zeros = torch.zeros(2, len(verts), HID)
    h0, c0 = cell.cell(x, table, valid)
    h1, c1 = cell.cell(x, table, valid, (zeros, zeros))
    torch.testing.assert_close(h0, h1, rtol=1e-6, atol=1e-7)  # the last bit: SIMD and scalar sigmoid differ
    torch.testing.assert_close(c0, c1, rtol=1e-6, atol=1e-7)
    h1.sum().backward()
    assert all(torch.isfinite(p.grad).all() for p in cell.parameters() if p.grad is not None)
