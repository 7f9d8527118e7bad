"""The hand-written back-propagation through time against torch's GRU: outputs and every gradient."""

from __future__ import annotations

import pytest
import torch

from loosefit.models.layers.gru import GRUHead
from loosefit.models.layers.gru_bptt import gru_bptt, gru_layers


def _grads(fn, gru, x, h0):
    """Outputs and the gradients of a loss on every output and the last state, w.r.t. inputs and parameters."""
    gru.zero_grad()
    x = x.detach().clone().requires_grad_(True)
    h0 = None if h0 is None else h0.detach().clone().requires_grad_(True)
    out, last = fn(gru, x, h0)
    (out.sin().sum() + (last * torch.linspace(-1, 1, last.shape[-1])).sum()).backward()
    grads = [x.grad] + ([] if h0 is None else [h0.grad]) + [p.grad.clone() for p in gru.parameters()]
    return out.detach(), last.detach(), grads


@pytest.mark.parametrize("layers,with_state", [(1, False), (1, True), (2, True)])
def test_outputs_and_gradients_equal_torchs_gru(layers, with_state):
    torch.manual_seed(0)
    gru = torch.nn.GRU(7, 11, num_layers=layers, batch_first=True).double()
    x = torch.randn(3, 13, 7, dtype=torch.float64)
    h0 = torch.randn(layers, 3, 11, dtype=torch.float64) if with_state else None
    ref = _grads(lambda g, a, b: g(a, b), gru, x, h0)
    new = _grads(gru_bptt, gru, x, h0)
    torch.testing.assert_close(new[0], ref[0], rtol=0, atol=1e-12)
    torch.testing.assert_close(new[1], ref[1], rtol=0, atol=1e-12)
    assert len(new[2]) == len(ref[2])
    for a, b in zip(new[2], ref[2]):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-12)


def test_gradient_of_the_last_state_alone_and_frozen_inputs():
    # only the last state in the loss (no output gradient) and inputs that need no gradient: the weights' gradients
    # still equal torch's, checked against finite differences of one weight
    torch.manual_seed(1)
    gru = torch.nn.GRU(4, 5, batch_first=True).double()
    x = torch.randn(2, 6, 4, dtype=torch.float64)
    w_ih, w_hh, b_ih, b_hh = gru.weight_ih_l0, gru.weight_hh_l0, gru.bias_ih_l0, gru.bias_hh_l0
    h0 = torch.zeros(2, 5, dtype=torch.float64)
    _, last = gru_layers(x[None], h0[None], w_ih[None], w_hh[None], b_ih[None], b_hh[None])
    last.sum().backward()
    eps, (i, j) = 1e-6, (7, 3)
    with torch.no_grad():
        w_hh[i, j] += eps
        up = gru(x)[1].sum()
        w_hh[i, j] -= 2 * eps
        down = gru(x)[1].sum()
        w_hh[i, j] += eps
    assert w_hh.grad[i, j].item() == pytest.approx(((up - down) / (2 * eps)).item(), rel=1e-6)


def test_gru_head_trains_through_it_and_streams_through_torch():
    # with autograd on (training, CPU) GRUHead runs the hand-written pass, without it torch's kernel: the same numbers
    torch.manual_seed(2)
    head = GRUHead(5, 8, 3)
    x = torch.randn(2, 9, 5)
    y_train, h_train = head(x)
    with torch.no_grad():
        y_eval, h_eval = head(x)
    assert y_train.requires_grad and not y_eval.requires_grad
    torch.testing.assert_close(y_train.detach(), y_eval, rtol=0, atol=1e-6)
    torch.testing.assert_close(h_train.detach(), h_eval, rtol=0, atol=1e-6)
