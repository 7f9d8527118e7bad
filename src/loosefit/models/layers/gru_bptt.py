"""GRU layers with a hand-written back-propagation through time, for training on the CPU.

torch's CPU GRU is differentiated step by step by autograd: at every time step its backward pass multiplies
the weight gradient of the recurrent matrix out and adds it into the ``(3H, H)`` gradient (a 4 MB read and
write per step for VirtualBones' 600 units), and copies the step's intermediates. Measured on the 2-core
machine (``benchmarks/experiments/gru_speed.py``, ``gru-speed.json``): forward and backward of a 600-unit GRU
over 90 frames of 4 windows, 383 ms, against 187 ms here (the forward pass alone: 83 ms). Here the forward
pass keeps every step's gates, the backward pass carries only the state's gradient from step to step (one ``(B, 3H) x (3H, H)`` product
per step) and forms the weight and input gradients once for the whole sequence, as three large products. ``G``
independent GRUs (JointNet's joints) run as one batched product per step: 305 against 1,009 ms for JointNet's 24
joints at the demo's sizes, where torch's kernel ran joint by joint.

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


#: An ``nn.GRU`` layer's parameters, in :func:`gru_layers`' order (each name ends in ``_l<layer>``).
PARAMETERS = ("weight_ih", "weight_hh", "bias_ih", "bias_hh")


class _GRUSequence(torch.autograd.Function):
    """``G`` independent GRU layers over whole sequences, with the backward pass of the module doc.

    Shapes: x ``(G, B, T, in)``, h0 ``(G, B, H)``, w_ih ``(G, 3H, in)``, w_hh ``(G, 3H, H)``, b_ih and b_hh ``(G, 3H)``
    -> outputs ``(G, B, T, H)``, last state ``(G, B, H)``. Each step is one batched product over the groups."""

    @staticmethod
    def forward(ctx, x, h0, w_ih, w_hh, b_ih, b_hh):
        G, B, T, _ = x.shape
        H = h0.shape[-1]
        # every step's input part at once
        gi = torch.baddbmm(b_ih[:, None], x.reshape(G, B * T, -1), w_ih.transpose(1, 2)).view(G, B, T, 3 * H)
        out = x.new_empty(G, B, T, H)
        gates = x.new_empty(G, B, T, 4, H)  # r, z, n and the recurrent part of n (W_hn h + b_hn)
        h = h0
        w_hh_t, b_hh = w_hh.transpose(1, 2), b_hh[:, None]
        for t in range(T):
            gh = torch.baddbmm(b_hh, h, w_hh_t)
            rz = torch.sigmoid(gi[:, :, t, :2 * H] + gh[..., :2 * H])
            r, z = rz[..., :H], rz[..., H:]
            ghn = gh[..., 2 * H:]
            n = torch.tanh(torch.addcmul(gi[:, :, t, 2 * H:], r, ghn))
            h = torch.lerp(n, h, z)  # (1 - z) n + z h
            out[:, :, t] = h
            gates[:, :, t, :2] = rz.view(G, B, 2, H)
            gates[:, :, t, 2] = n
            gates[:, :, t, 3] = ghn
        ctx.save_for_backward(x, h0, w_ih, w_hh, out, gates)
        return out, h

    @staticmethod
    def backward(ctx, d_out, d_last):
        x, h0, w_ih, w_hh, out, gates = ctx.saved_tensors
        G, B, T, H = out.shape
        prev = torch.cat([h0[:, :, None], out[:, :, :-1]], 2)  # the state each step starts from, (G, B, T, H)
        d_gi = x.new_empty(G, B, T, 3 * H)
        d_gh = x.new_empty(G, B, T, 3 * H)
        dh = d_last.clone() if d_last is not None else x.new_zeros(G, B, H)
        for t in range(T - 1, -1, -1):
            if d_out is not None:
                dh = dh + d_out[:, :, t]
            r, z, n, ghn = gates[:, :, t].unbind(2)
            da_n = dh * (1 - z) * (1 - n * n)  # through h' = (1 - z) n + z h and n = tanh(a_n)
            da_r = da_n * ghn * r * (1 - r)
            da_z = dh * (prev[:, :, t] - n) * z * (1 - z)
            d_gi[:, :, t, :H], d_gi[:, :, t, H:2 * H], d_gi[:, :, t, 2 * H:] = da_r, da_z, da_n
            d_gh[:, :, t, :H], d_gh[:, :, t, H:2 * H], d_gh[:, :, t, 2 * H:] = da_r, da_z, da_n * r
            dh = torch.baddbmm(dh * z, d_gh[:, :, t], w_hh)
        flat_gi, flat_gh = d_gi.view(G, B * T, 3 * H), d_gh.view(G, B * T, 3 * H)
        d_x = torch.bmm(flat_gi, w_ih).view_as(x) if ctx.needs_input_grad[0] else None
        d_w_ih = torch.bmm(flat_gi.transpose(1, 2), x.reshape(G, B * T, -1)) if ctx.needs_input_grad[2] else None
        d_w_hh = torch.bmm(flat_gh.transpose(1, 2), prev.reshape(G, B * T, H)) if ctx.needs_input_grad[3] else None
        d_b_ih = flat_gi.sum(1) if ctx.needs_input_grad[4] else None
        d_b_hh = flat_gh.sum(1) if ctx.needs_input_grad[5] else None
        return d_x, dh, d_w_ih, d_w_hh, d_b_ih, d_b_hh


def by_hand(x: torch.Tensor) -> bool:
    """Whether ``x`` goes through the hand-written pass: autograd on and the tensor on the CPU. Without autograd
    torch's fused kernel is faster, and on CUDA cuDNN's."""
    return torch.is_grad_enabled() and x.device.type == "cpu"


def gru_layers(x: torch.Tensor, h0: torch.Tensor, w_ih: torch.Tensor, w_hh: torch.Tensor, b_ih: torch.Tensor,
               b_hh: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``G`` independent GRU layers with torch's weight layout, differentiated by :class:`_GRUSequence`.

    Shapes: x ``(G, B, T, in)``, h0 ``(G, B, H)``, w_ih ``(G, 3H, in)``, w_hh ``(G, 3H, H)``, b_ih and b_hh ``(G, 3H)``
    -> outputs ``(G, B, T, H)``, last states ``(G, B, H)``."""
    return _GRUSequence.apply(x, h0, w_ih, w_hh, b_ih, b_hh)


def gru_bptt(gru: nn.GRU, x: torch.Tensor, h: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """``gru(x, h)``: for a unidirectional, batch-first ``nn.GRU`` with biases and no dropout, where :func:`by_hand`
    says so, differentiated by :class:`_GRUSequence` (see the module doc); otherwise torch's own.

    Shapes: x ``(B, T, in)``, h ``(layers, B, hidden)`` or None (zeros) -> ``(B, T, hidden)``, ``(layers, B, hidden)``.
    """
    if (not by_hand(x) or gru.bidirectional or not gru.batch_first or not gru.bias or (gru.dropout and gru.training)
            or gru.proj_size):
        return gru(x, h)
    if h is None:
        h = x.new_zeros(gru.num_layers, x.shape[0], gru.hidden_size)
    last = []
    for k in range(gru.num_layers):
        out, h_k = gru_layers(x[None], h[k][None], *(getattr(gru, f"{name}_l{k}")[None] for name in PARAMETERS))
        x = out[0]
        last.append(h_k[0])
    return x, torch.stack(last)
