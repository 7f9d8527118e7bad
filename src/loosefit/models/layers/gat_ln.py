"""GAT-LN: graph attention with Lipschitz-normalised scores (SwinGar Eq. 4, after Dasoulas et al. 2021).

Per head ``h`` and mesh edge (or self loop) ``j -> i`` the plain graph attention score is linear in the
two endpoint features (SwinGar Eq. 2, the score function ``g``)::

    s_ij = a_dst_h . (W_h x_i) + a_src_h . (W_h x_j) = c_dst_h . x_i + c_src_h . x_j

SwinGar Eq. 4 divides it, per graph and head, by the larger of two norms and scales it by ``alpha``::

    g*_ij = alpha s_ij / max( max_i ||s_i.||_2 ,  max_i ||x_i||_2 * ||[c_dst_h, c_src_h]||_2 )

- ``max_i ||s_i.||_2``: the (2, inf)-norm of the masked score matrix (largest row norm over each
  vertex's neighbourhood);
- ``max_i ||x_i||_2``: the (inf, 2)-norm of the input features; ``||[c_dst, c_src]||_2``: the
  spectral norm of the (linear) score function's parameters, its Lipschitz constant.

Every normalised score lies in ``[-alpha, alpha]`` and the scores no longer depend on the scale of the
input, so the layer without its output activation is positively homogeneous: ``f(s X) = s f(X)`` for
``s > 0`` (up to the bias). Its Lipschitz constant therefore does not grow with the input's scale
(plain GAT's does: its softmax sharpens), and is set by ``alpha``: the smaller ``alpha``, the closer
the attention to a plain neighbourhood mean (SwinGar Eq. 5 bounds the Fourier coefficients by
``(e^alpha sqrt(b/N) + alpha sqrt(8)) / k^2``).

After normalisation come GAT's LeakyReLU (slope 0.2, which keeps ``|g*| <= alpha``) and a softmax
over each vertex's neighbours and itself. The heads' aggregated features ``sum_j P_ij W_h x_j`` are
averaged (not concatenated: the output width is the hidden size SwinGar gives, at any head count),
a bias is added and ``tanh`` applied (SwinGar Sec. IV: every GAT-LN layer uses tanh; ``activation=None``
leaves it out, as the gate maps of :mod:`loosefit.models.layers.lstm_gat_ln` need). ``alpha=None``
switches the normalisation off: the plain GAT layer of SwinGar's ablation (Fig. 8, 9).

Departures, named: the normaliser is global, one per graph and head, as SwinGar Eq. 4's matrix norms read
(the largest row norm over the whole graph, the largest feature norm over the whole graph), where the
Lipschitz normalisation SwinGar cites (Dasoulas et al. 2021) divides each node's scores by a norm of its own;
with one normaliser a vertex's scores also depend on the largest scores elsewhere in the graph. The heads are
averaged, where GAT (and FitGar's blocks, :mod:`loosefit.models.layers.gat_block`) concatenate them: SwinGar
gives each layer one hidden size and 24 heads without saying which; concatenated, a 128-wide layer of 24 heads
would need a width divisible by 24.

The graph is a padded neighbour table (:func:`attention_table`) rather than PyG's edge list: the
forward pass then scatters nothing (the backward pass scatters one value per vertex, slot and input
channel), which matters on CPUs where torch's scatter is slow with several threads. Since
``sum_j P_ij W_h x_j = W_h sum_j P_ij x_j``, the inputs are aggregated per head first and projected once
by all heads' stacked weights: the neighbour gather moves ``in`` channels instead of ``heads * out``
(SwinGar at the paper's sizes on a 2.8k-vertex dress, one CPU thread: 2.7 s a frame the other way
round, 0.2 s this way).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.geometry.laplacian import edges

#: Slope of GAT's LeakyReLU on the attention scores (Velickovic et al. 2018).
SCORE_SLOPE = 0.2
#: Smallest normaliser of the scores: an all-zero input (a zero recurrent state) gives zero scores.
NORM_EPS = 1e-12


def attention_table(faces: np.ndarray, num_verts: int) -> tuple[np.ndarray, np.ndarray]:
    """The attention neighbourhoods of a triangle mesh: every vertex and its edge neighbours.

    Args:
        faces: ``(F, 3)`` int triangles (``F`` may be 0: then every vertex attends to itself only).
        num_verts: ``V``.

    Returns:
        ``table (V, D)`` int64 (slot 0 is the vertex itself, then its neighbours in increasing order,
        padded with the vertex itself) and ``valid (V, D)`` bool (False on padding), ``D`` one more
        than the largest degree.
    """
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    if len(faces) and (faces.min() < 0 or faces.max() >= num_verts):
        raise InputError(f"faces index vertices outside [0, {num_verts})")
    e = edges(faces) if len(faces) else np.zeros((0, 2), np.int64)
    both = np.concatenate([e, e[:, ::-1]])
    both = both[np.lexsort((both[:, 1], both[:, 0]))]
    degree = np.bincount(both[:, 0], minlength=num_verts)
    width = int(degree.max(initial=0)) + 1
    table = np.repeat(np.arange(num_verts, dtype=np.int64)[:, None], width, 1)
    valid = np.zeros((num_verts, width), bool)
    valid[:, 0] = True
    start = np.concatenate([[0], np.cumsum(degree)[:-1]]).astype(np.int64)
    for slot in range(width - 1):
        has = degree > slot
        table[has, slot + 1] = both[start[has] + slot, 1]
        valid[has, slot + 1] = True
    return table, valid


class GATLN(nn.Module):
    """One GAT-LN layer ``(..., V, in) -> (..., V, out)`` over an attention table (SwinGar Eq. 4).

    Args:
        in_channels, out_channels: feature sizes.
        heads: attention heads (averaged).
        alpha: the score scale of SwinGar Eq. 4 (2 in the paper); ``None``: no normalisation (plain GAT).
        activation: ``"tanh"`` (SwinGar) or ``None`` (linear output).

    Parameters are initialised with Glorot's uniform rule (SwinGar Sec. IV), the bias with zeros.

    Shapes:
        x ``(..., V, in_channels)``, table and valid ``(V, D)`` (:func:`attention_table`) ->
        ``(..., V, out_channels)``.
    """

    def __init__(self, in_channels: int, out_channels: int, heads: int = 1, alpha: float | None = 2.0,
                 activation: str | None = "tanh"):
        super().__init__()
        if min(in_channels, out_channels, heads) < 1:
            raise InputError(f"GAT-LN sizes must be >= 1, got in {in_channels}, out {out_channels}, heads {heads}")
        if alpha is not None and not alpha >= 0:
            raise InputError(f"GAT-LN alpha must be >= 0 (or None for plain GAT), got {alpha}")
        if activation not in ("tanh", None):
            raise InputError(f"GAT-LN activation must be 'tanh' or None, got {activation!r}")
        self.in_channels, self.out_channels, self.heads = in_channels, out_channels, heads
        self.alpha, self.activation = alpha, activation
        self.weight = nn.Parameter(torch.empty(in_channels, heads * out_channels))
        self.att_dst = nn.Parameter(torch.empty(heads, out_channels))
        self.att_src = nn.Parameter(torch.empty(heads, out_channels))
        self.bias = nn.Parameter(torch.zeros(out_channels))
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """Glorot uniform weights (per head for the projection), zero bias."""
        bound = math.sqrt(6.0 / (self.in_channels + self.out_channels))
        nn.init.uniform_(self.weight, -bound, bound)
        bound = math.sqrt(6.0 / (1 + self.out_channels))
        nn.init.uniform_(self.att_dst, -bound, bound)
        nn.init.uniform_(self.att_src, -bound, bound)
        nn.init.zeros_(self.bias)

    def extra_repr(self) -> str:
        return f"{self.in_channels}, {self.out_channels}, heads={self.heads}, alpha={self.alpha}, activation={self.activation}"

    def score_vectors(self) -> tuple[torch.Tensor, torch.Tensor]:
        """``c_dst, c_src (H, in)``: the score function as linear forms on the input features."""
        W = self.weight.view(self.in_channels, self.heads, self.out_channels)
        return torch.einsum("chk,hk->hc", W, self.att_dst), torch.einsum("chk,hk->hc", W, self.att_src)

    def attention(self, x: torch.Tensor, table: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """Attention weights ``P (B, V, D, H)`` (rows sum to 1 over the valid slots) of ``x (B, V, in)``."""
        c_dst, c_src = self.score_vectors()
        u_dst, u_src = x @ c_dst.T, x @ c_src.T  # (B, V, H)
        s = u_dst[:, :, None] + u_src[:, table]  # (B, V, D, H) linear scores
        mask = valid[None, :, :, None]
        if self.alpha is not None:
            s = s * mask
            # square roots clamped away from 0: their gradient there is infinite (a zero recurrent state)
            tiny = NORM_EPS * NORM_EPS
            row = s.square().sum(2).clamp_min(tiny).sqrt().amax(1)  # (B, H): (2, inf)-norm of the score matrix
            lip = (c_dst.square().sum(-1) + c_src.square().sum(-1)).clamp_min(tiny).sqrt()  # (H,)
            feat = x.square().sum(-1).clamp_min(tiny).sqrt().amax(1, keepdim=True)  # (B, 1): (inf, 2)-norm of the features
            s = self.alpha * s / torch.maximum(row, feat * lip)[:, None, None]
        s = nn.functional.leaky_relu(s, SCORE_SLOPE).masked_fill(~mask, float("-inf"))
        return torch.softmax(s, 2)

    def forward(self, x: torch.Tensor, table: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """``x (..., V, in)``, ``table``/``valid (V, D)`` from :func:`attention_table` -> ``(..., V, out)``."""
        if x.shape[-1] != self.in_channels or x.shape[-2] != table.shape[0]:
            raise InputError(f"GAT-LN expects (..., {table.shape[0]}, {self.in_channels}) features, got {tuple(x.shape)}")
        lead = x.shape[:-2]
        x = x.reshape(-1, *x.shape[-2:])
        P = self.attention(x, table, valid)  # (B, V, D, H)
        # sum_j P_ijh W_h x_j = W_h (sum_j P_ijh x_j): aggregate the inputs per head, then one product with
        # the heads' stacked projections (which also averages them)
        gathered = x.index_select(1, table.reshape(-1)).unflatten(1, table.shape)  # (B, V, D, in)
        z = torch.einsum("bvdh,bvdc->bvhc", P, gathered)  # (B, V, H, in)
        W = self.weight.view(self.in_channels, self.heads, self.out_channels).transpose(0, 1)
        out = z.flatten(-2) @ W.reshape(self.heads * self.in_channels, self.out_channels) / self.heads + self.bias
        if self.activation == "tanh":
            out = torch.tanh(out)
        return out.reshape(*lead, *out.shape[-2:])
