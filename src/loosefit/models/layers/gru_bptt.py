"""A GRU layer with a hand-written back-propagation through time, for training on the CPU.

torch's CPU GRU is differentiated step by step by autograd: at every time step its backward pass multiplies
the weight gradient of the recurrent matrix out and adds it into the ``(3H, H)`` gradient (a 4 MB read and
write per step for VirtualBones' 600 units), and copies the step's intermediates. Measured on the 2-core
machine (``benchmarks/gru_speed.py``, ``gru-speed.json``): forward and backward of a 600-unit GRU over 90 frames
of 4 windows took 481 ms, ten times the forward pass alone (49 ms). Here the forward pass keeps every step's
gates, the backward pass carries only the state's gradient from step to step (one ``(B, 3H) x (3H, H)``
product per step) and forms the weight and input gradients once for the whole sequence, as three large
products: 198 ms, and a VirtualBones training step of the low-frequency stage 464 against 746 ms. JointNet's
per-joint GRUs (128-256 units) gained nothing measurable (62-82 ms either way), so they keep torch's kernel.

The equations are torch's (``torch.nn.GRU``, gates in the order r, z, n)::

    r = sigmoid(W_ir x + b_ir + W_hr h + b_hr)
    z = sigmoid(W_iz x + b_iz + W_hz h + b_hz)
    n = tanh(W_in x + b_in + r * (W_hn h + b_hn))
    h' = (1 - z) * n + z * h

so the parameters of an ``nn.GRU`` layer run here unchanged (``tests/models/layers/test_gru_bptt.py``: outputs and
every gradient against ``nn.GRU``'s).
"""

from __future__ import annotations

import torch
from torch import nn


class _GRUSequence(torch.autograd.Function):
    """One GRU layer over a whole sequence, with the backward pass of the module doc."""

    @staticmethod
    def forward(ctx, x, h0, w_ih, w_hh, b_ih, b_hh):
        B, T, _ = x.shape
        H = h0.shape[-1]
        gi = torch.addmm(b_ih, x.reshape(B * T, -1), w_ih.t()).view(B, T, 3 * H)  # every step's input part at once
        out = x.new_empty(B, T, H)
        gates = x.new_empty(B, T, 4, H)  # r, z, n and the recurrent part of n (W_hn h + b_hn)
        h = h0
        w_hh_t = w_hh.t()
        for t in range(T):
            gh = torch.addmm(b_hh, h, w_hh_t)
            rz = torch.sigmoid(gi[:, t, :2 * H] + gh[:, :2 * H])
            r, z = rz[:, :H], rz[:, H:]
            ghn = gh[:, 2 * H:]
            n = torch.tanh(torch.addcmul(gi[:, t, 2 * H:], r, ghn))
            h = torch.lerp(n, h, z)  # (1 - z) n + z h
            out[:, t] = h
            gates[:, t, :2] = rz.view(B, 2, H)
            gates[:, t, 2] = n
            gates[:, t, 3] = ghn
        ctx.save_for_backward(x, h0, w_ih, w_hh, out, gates)
        return out, h

    @staticmethod
    def backward(ctx, d_out, d_last):
        x, h0, w_ih, w_hh, out, gates = ctx.saved_tensors
        B, T, H = out.shape
        prev = torch.cat([h0[:, None], out[:, :-1]], 1)  # the state each step starts from, (B, T, H)
        d_gi = x.new_empty(B, T, 3 * H)
        d_gh = x.new_empty(B, T, 3 * H)
        dh = d_last.clone() if d_last is not None else x.new_zeros(B, H)
        for t in range(T - 1, -1, -1):
            if d_out is not None:
                dh = dh + d_out[:, t]
            r, z, n, ghn = gates[:, t].unbind(1)
            da_n = dh * (1 - z) * (1 - n * n)  # through h' = (1 - z) n + z h and n = tanh(a_n)
            da_r = da_n * ghn * r * (1 - r)
            da_z = dh * (prev[:, t] - n) * z * (1 - z)
            d_gi[:, t, :H], d_gi[:, t, H:2 * H], d_gi[:, t, 2 * H:] = da_r, da_z, da_n
            d_gh[:, t, :H], d_gh[:, t, H:2 * H], d_gh[:, t, 2 * H:] = da_r, da_z, da_n * r
            dh = torch.addmm(dh * z, d_gh[:, t], w_hh)
        flat_gi, flat_gh = d_gi.view(B * T, 3 * H), d_gh.view(B * T, 3 * H)
        d_x = (flat_gi @ w_ih).view_as(x) if ctx.needs_input_grad[0] else None
        d_w_ih = flat_gi.t() @ x.reshape(B * T, -1) if ctx.needs_input_grad[2] else None
        d_w_hh = flat_gh.t() @ prev.reshape(B * T, H) if ctx.needs_input_grad[3] else None
        d_b_ih = flat_gi.sum(0) if ctx.needs_input_grad[4] else None
        d_b_hh = flat_gh.sum(0) if ctx.needs_input_grad[5] else None
        return d_x, dh, d_w_ih, d_w_hh, d_b_ih, d_b_hh


def gru_layer(x: torch.Tensor, h0: torch.Tensor, w_ih: torch.Tensor, w_hh: torch.Tensor, b_ih: torch.Tensor,
              b_hh: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """One GRU layer with torch's weight layout (``w_ih (3H, in)``, ``w_hh (3H, H)``, biases ``(3H,)``), differentiated
    by :class:`_GRUSequence`. Shapes: x ``(B, T, in)``, h0 ``(B, H)`` -> outputs ``(B, T, H)``, last state ``(B, H)``."""
    return _GRUSequence.apply(x, h0, w_ih, w_hh, b_ih, b_hh)


def gru_bptt(gru: nn.GRU, x: torch.Tensor, h: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """``gru(x, h)`` for a unidirectional, batch-first ``nn.GRU`` with biases and no dropout, differentiated by
    :class:`_GRUSequence` (see the module doc).

    Shapes: x ``(B, T, in)``, h ``(layers, B, hidden)`` or None (zeros) -> ``(B, T, hidden)``, ``(layers, B, hidden)``.
    """
    if gru.bidirectional or not gru.batch_first or not gru.bias or (gru.dropout and gru.training) or gru.proj_size:
        return gru(x, h)  # not this layer's case: torch's own
    if h is None:
        h = x.new_zeros(gru.num_layers, x.shape[0], gru.hidden_size)
    last = []
    for k in range(gru.num_layers):
        x, h_k = gru_layer(x, h[k], getattr(gru, f"weight_ih_l{k}"), getattr(gru, f"weight_hh_l{k}"),
                           getattr(gru, f"bias_ih_l{k}"), getattr(gru, f"bias_hh_l{k}"))
        last.append(h_k)
    return x, torch.stack(last)
