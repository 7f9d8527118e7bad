"""LSTM-GAT-LN: an LSTM over a sequence of graphs whose maps are GAT-LN layers (SwinGar Eq. 6, Fig. 5).

For node features ``X^t (V, in)`` of a fixed graph, hidden state ``H`` and cell state ``C`` ``(V, hidden)``::

    i^t = sigma(A_i(X^t) + S_i(H^{t-1}) + w_i o C^{t-1})
    f^t = sigma(A_f(X^t) + S_f(H^{t-1}) + w_f o C^{t-1})
    o^t = sigma(A_o(X^t) + S_o(H^{t-1}) + w_o o C^{t-1})
    C^t = i^t o tanh(A_g(X^t) + S_g(H^{t-1})) + f^t o C^{t-1}
    H^t = o^t o tanh(C^t)

``A`` (input-to-state) and ``S`` (state-to-state) are GAT-LN maps (:mod:`loosefit.models.layers.gat_ln`)
without output activation, each giving the four gates' pre-activations at once (``4 * hidden`` channels in
torch's gate order i, f, g, o), and ``w_i, w_f, w_o (hidden,)`` are the peephole weights on the previous cell
state, as SwinGar Eq. 6 writes them (all three on ``C^{t-1}``).

``per_gate=True`` gives each gate a GAT-LN of its own, as Eq. 6 writes (``A_i, A_f, A_g, A_o``, each with
``heads`` heads and its own attention): one layer of ``4 * heads`` concatenated heads in four groups
(:class:`~loosefit.models.layers.gat_ln.GATLN`'s ``groups``), which computes exactly the four layers side by
side with one neighbour gather. ``per_gate=False`` (the layer as loosefit first built it) shares one attention
per head across the four gates (their projections are separate columns of the one layer).

The peepholes start at zero, so with every node attending only to itself and one head (per gate) the cell is
exactly ``torch.nn.LSTMCell`` applied per node (``A``'s weight and bias are ``weight_ih.T`` and
``bias_ih``, ``S``'s are ``weight_hh.T`` and ``bias_hh``).

Departures from SwinGar Eq. 6, named:

- with ``per_gate=False`` one GAT-LN per map serves all four gates, where Eq. 6 writes a GAT-LN per gate;
- Eq. 6 prints ``C^t = i^t o tanh(A(X^t) + S(H^{t-1}) + f^t o C^{t-1})``, the forget term inside the tanh;
  here it is outside, ``C^t = i^t o tanh(A_g + S_g) + f^t o C^{t-1}``, the standard LSTM cell update, which
  the parenthesis most likely misprints (inside, a closed input gate would erase the cell whatever the forget
  gate says, and the forget gate would not gate the memory);
- the paper does not say how the peepholes start; zero here (the cell starts as a plain LSTM).
"""

from __future__ import annotations

import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.models.layers.gat_ln import GATLN
from loosefit.models.layers.init import undrawn


def _tanh(x: torch.Tensor) -> torch.Tensor:
    """``tanh``; on the CPU without autograd as ``2 sigmoid(2 x) - 1`` (absolute error near 1e-7): torch's CPU tanh
    takes about ten times its sigmoid's time here (573k values: 1.1 ms against 0.12), a tenth of SwinGar's streaming
    frame once its GAT-LN layers run fused."""
    if x.device.type != "cpu" or torch.is_grad_enabled():
        return torch.tanh(x)
    return torch.sigmoid(2.0 * x).mul_(2.0).sub_(1.0)


class LSTMGATLN(nn.Module):
    """The LSTM-GAT-LN cell and its loop over frames.

    Args:
        in_channels: node feature size of the input graphs.
        hidden: hidden and cell state size per node.
        heads: attention heads of both maps.
        alpha: GAT-LN score scale (SwinGar Eq. 4); None for plain GAT maps.
        per_gate: one GAT-LN per gate (SwinGar Eq. 6; concatenated heads) instead of one per map.
        attention: further :class:`~loosefit.models.layers.gat_ln.GATLN` options of both maps (``norm``,
            ``centred``, ``concat``).

    Shapes:
        x ``(..., T, V, in_channels)``, table and valid ``(V, D)``, state ``(H, C)`` each ``(..., V, hidden)`` or
        None -> hidden states ``(..., T, V, hidden)`` and the last ``(H, C)``.
    """

    def __init__(self, in_channels: int, hidden: int, heads: int = 1, alpha: float | None = 2.0,
                 per_gate: bool = False, **attention):
        super().__init__()
        if hidden < 1:
            raise InputError(f"LSTM-GAT-LN hidden size must be >= 1, got {hidden}")
        if per_gate and not attention.get("concat", False):
            raise InputError("LSTM-GAT-LN: a GAT-LN per gate needs concatenated heads (concat=True)")
        self.hidden, self.per_gate = hidden, bool(per_gate)
        maps = dict(heads=4 * heads, groups=4) if per_gate else dict(heads=heads)
        self.input_map = undrawn(GATLN, in_channels, 4 * hidden, alpha=alpha, activation=None, **maps, **attention)
        self.state_map = undrawn(GATLN, hidden, 4 * hidden, alpha=alpha, activation=None, **maps, **attention)
        self.peephole = nn.Parameter(torch.empty(3, hidden))  # w_i, w_f, w_o
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """The two maps' Glorot initialisation (input map, then state map), zero peepholes."""
        self.input_map.reset_parameters()
        self.state_map.reset_parameters()
        nn.init.zeros_(self.peephole)

    def extra_repr(self) -> str:
        return f"hidden={self.hidden}, per_gate={self.per_gate}"

    def cell(self, x: torch.Tensor, table: torch.Tensor, valid: torch.Tensor,
             state: tuple[torch.Tensor, torch.Tensor] | None = None,
             x_gates: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """One step (SwinGar Eq. 6): ``x (..., V, in)``, ``state (H, C)`` each ``(..., V, hidden)`` or None
        (zeros) -> the new ``(H, C)``. ``x_gates``: ``self.input_map(x)`` when already computed.

        From a zero state the state map is not run: zero features aggregate to zero under any attention, so
        ``S(0)`` is the map's bias, and the peepholes see a zero cell (the same values to the last bit or so,
        without the graph pass: a third of SwinGar's corrective state maps, which start every frame from zeros)."""
        gx = self.input_map(x, table, valid) if x_gates is None else x_gates
        if state is None:
            gi, gf, gg, go = (gx + self.state_map.bias).chunk(4, -1)
            c = torch.sigmoid(gi) * _tanh(gg)  # SwinGar Eq. 6 from H, C = 0
            return torch.sigmoid(go) * _tanh(c), c
        h, c = state
        gates = gx + self.state_map(h, table, valid)
        gi, gf, gg, go = gates.chunk(4, -1)
        i = torch.sigmoid(gi + self.peephole[0] * c)  # SwinGar Eq. 6, i^t
        f = torch.sigmoid(gf + self.peephole[1] * c)  # SwinGar Eq. 6, f^t
        o = torch.sigmoid(go + self.peephole[2] * c)  # SwinGar Eq. 6, o^t
        c = i * _tanh(gg) + f * c  # SwinGar Eq. 6, C^t (forget term outside the tanh)
        return o * _tanh(c), c

    def forward(self, x: torch.Tensor, table: torch.Tensor, valid: torch.Tensor,
                state: tuple[torch.Tensor, torch.Tensor] | None = None):
        """A sequence ``x (..., T, V, in)`` -> hidden states ``(..., T, V, hidden)`` and the last ``(H, C)``.

        The input-to-state map of every frame is computed in one call before the loop."""
        if x.dim() < 3:
            raise InputError(f"LSTM-GAT-LN expects a sequence (..., T, V, in), got {tuple(x.shape)}")
        gx = self.input_map(x, table, valid)
        outputs = []
        for t in range(x.shape[-3]):
            state = self.cell(x[..., t, :, :], table, valid, state, x_gates=gx[..., t, :, :])
            outputs.append(state[0])
        return torch.stack(outputs, -3), state
