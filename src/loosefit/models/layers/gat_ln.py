"""GAT-LN: graph attention with Lipschitz-normalised scores (SwinGar Eq. 4, after Dasoulas et al. 2021).

Per head ``h`` and mesh edge (or self loop) ``j -> i`` the plain graph attention score is linear in the
two endpoint features (SwinGar Eq. 2, the score function ``g``)::

    s_ij = a_dst_h . (W_h x_i) + a_src_h . (W_h x_j) = c_dst_h . x_i + c_src_h . x_j

SwinGar Eq. 4 divides it by the larger of two norms and scales it by ``alpha``::

    g*_ij = alpha s_ij / max( ||s||_(2,inf) ,  ||X||_(inf,2) * ||[c_dst_h, c_src_h]||_2 )

- ``||s||_(2,inf)``: the largest row norm of the masked score matrix (each row: one vertex's scores over
  its neighbourhood);
- ``||X||_(inf,2)``: the largest feature norm; ``||[c_dst, c_src]||_2``: the spectral norm of the (linear)
  score function's parameters, its Lipschitz constant.

``norm`` says over what the two norms are taken:

- ``"graph"``: over the whole graph, one normaliser per graph and head, as Eq. 4's matrix norms read;
- ``"node"``: per vertex ``i``, its own row ``||s_i.||_2`` and the largest feature norm of its neighbourhood
  ``max_{j in N(i)} ||x_j||``: the per-node Lipschitz normalisation of Dasoulas et al., which Eq. 4 cites. A
  vertex's scores then no longer depend on the largest scores or features elsewhere in the graph;
- ``"row"`` (ours): per vertex, its own row norm ``||s_i.||_2`` alone, without the feature bound. Each row of
  normalised scores then has norm ``alpha`` exactly, so ``alpha`` alone sets the attention's sharpness. Under
  ``"node"`` the bound term ``max ||x_j|| * ||[c_dst, c_src]||`` (a Cauchy-Schwarz worst case) is the larger of the
  two in most rows of a trained SwinGar, and its scores span a fraction of ``[-alpha, alpha]``
  (``benchmarks/experiments/LOG.md``). The scores stay within ``[-alpha, alpha]``, but the layer is no longer Lipschitz
  with a constant set by ``alpha``: a row of tiny scores is scaled up as much as a row of large ones.

``centred=True`` (ours) computes the scores and the feature norms from each neighbourhood's features minus
their mean, ``x_j - mu_i`` with ``mu_i`` the mean over ``i`` and its neighbours (edge-relative features). Why:
the score differences between two neighbours ``j, k`` of ``i``, which alone move the softmax, are
``c_src . (x_j - x_k)``; under Eq. 4 they are bounded by ``alpha |x_j - x_k| / max ||x||``. On mesh features
that vary smoothly over the surface (positions in metres, soles at ``z = 0``, and the hidden features of the
layers after them) that is a few hundredths of ``alpha``: every attention stays uniform and ``alpha`` is inert.
Centred, the bound is ``alpha |x_j - x_k| / max_j |x_j - mu_i|``, of order ``alpha``. Subtracting the
neighbourhood mean is linear, so the Lipschitz bound of Eq. 4 keeps its form.

Every normalised score lies in ``[-alpha, alpha]`` and the scores no longer depend on the scale of the input,
so the layer without its output activation is positively homogeneous: ``f(s X) = s f(X)`` for ``s > 0`` (up to
the bias). Its Lipschitz constant therefore does not grow with the input's scale (plain GAT's does: its softmax
sharpens), and is set by ``alpha``: the smaller ``alpha``, the closer the attention to a plain neighbourhood
mean (SwinGar Eq. 5 bounds the Fourier coefficients by ``(e^alpha sqrt(b/N) + alpha sqrt(8)) / k^2``).

After normalisation come GAT's LeakyReLU (slope 0.2, which keeps ``|g*| <= alpha``) and a softmax over each
vertex's neighbours and itself. The heads' aggregated features ``sum_j P_ij W_h x_j`` are then either

- averaged (``concat=False``): every head projects to all ``out`` channels and the output is their mean; or
- concatenated (``concat=True``, GAT's way): the ``out`` channels are split among the heads in contiguous
  blocks, head ``h`` computes only its block. Where ``out`` is a multiple of ``heads`` each head is
  ``out / heads`` wide; otherwise the block sizes differ by one (SwinGar's 128 channels over 24 heads: 8
  heads of 6 and 16 of 5), so that the layer keeps the width the paper gives.

``groups`` (concatenated heads only) splits the output into that many equal blocks, each with ``heads /
groups`` heads of its own: ``groups`` independent GAT-LN layers in one, as the four gate maps of
:mod:`loosefit.models.layers.lstm_gat_ln` need. A bias is added and ``tanh`` applied (SwinGar Sec. IV: every
GAT-LN layer uses tanh; ``activation=None`` leaves it out). ``alpha=None`` switches the normalisation off: the
plain GAT layer of SwinGar's ablation (Fig. 8, 9).

The defaults (``norm="graph"``, ``centred=False``, ``concat=False``) are the layer as loosefit first built it:
Eq. 4 as printed, heads averaged. :mod:`loosefit.models.swingar` chooses per model (its config says which,
and why).

The graph is a padded neighbour table (:func:`attention_table`). How the passes below run fast (the gathers,
the softmax and the sums over the table's slots, the aggregation of concatenated heads, the fused CPU kernel) is
:mod:`loosefit.models.layers.gat_ln_fast`; this module is the layer as the equations read.

:func:`recording_attention` records each layer's mean attention entropy per vertex (and that of a uniform
attention over the same neighbourhoods, its upper bound): how far the attention is from a mean filter.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np
import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.geometry.laplacian import edges
from loosefit.models.layers import gat_ln_fast as fast
from loosefit.models.layers.gat_ln_fast import centred_norms, gather_slots, neighbourhood_mean, slot_softmax

#: Slope of GAT's LeakyReLU on the attention scores (Velickovic et al. 2018).
SCORE_SLOPE = 0.2
#: Smallest normaliser of the scores: an all-zero input (a zero recurrent state) gives zero scores.
NORM_EPS = 1e-12
#: Values of ``GATLN(norm=...)``.
NORMS = ("graph", "node", "row")
#: Up to this ``alpha`` the normalised scores' exponentials stay far inside float32's range (e^40 ~ 2e17).
MAX_BOUNDED_ALPHA = 40.0


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


def head_columns(out_channels: int, heads: int, groups: int = 1) -> np.ndarray:
    """The head of each output channel of concatenated heads, ``(out_channels,)`` int64: ``groups`` equal
    blocks of channels, each split among its ``heads / groups`` heads in contiguous blocks whose sizes differ
    by at most one."""
    if heads % groups or out_channels % groups:
        raise InputError(f"GAT-LN: {heads} heads and {out_channels} channels do not split into {groups} groups")
    per_out, per_heads = out_channels // groups, heads // groups
    if per_out < per_heads:
        raise InputError(f"GAT-LN: {per_heads} concatenated heads need at least as many channels, got {per_out}")
    within = np.arange(per_out) * per_heads // per_out
    return np.concatenate([g * per_heads + within for g in range(groups)]).astype(np.int64)


def attention_entropy(P: torch.Tensor, valid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean entropy (nats) of the attention distributions ``P (B, V, D, H)`` (zero on padding) over batches,
    vertices and heads, and that of the uniform distribution over the same neighbourhoods, ``mean_i log |N(i)|``
    (its maximum): equal when the layer is a neighbourhood mean."""
    entropy = -(P * P.clamp_min(1e-30).log()).sum(2).mean()
    return entropy, valid.sum(1).double().log().mean().to(P.dtype)


def lipschitz(c_dst: torch.Tensor, c_src: torch.Tensor) -> torch.Tensor:
    """``(H,)``: the norm of each head's score function ``[c_dst, c_src]`` (SwinGar Eq. 4), kept off 0 (the square
    root's gradient there is infinite)."""
    # SwinGar Eq. 4's L_F(g)
    return (c_dst.square().sum(-1) + c_src.square().sum(-1)).clamp_min(NORM_EPS * NORM_EPS).sqrt()


class GATLN(nn.Module):
    """One GAT-LN layer ``(..., V, in) -> (..., V, out)`` over an attention table (SwinGar Eq. 4).

    Args:
        in_channels, out_channels: feature sizes.
        heads: attention heads (all groups together).
        alpha: the score scale of SwinGar Eq. 4 (2 in the paper); ``None``: no normalisation (plain GAT).
        activation: ``"tanh"`` (SwinGar) or ``None`` (linear output).
        norm: ``"graph"`` (Eq. 4's norms over the graph), ``"node"`` (per vertex) or ``"row"`` (per vertex, the
            score row's norm alone); see the module doc.
        centred: scores and norms from neighbourhood-centred features (see the module doc).
        concat: concatenate the heads (each its block of ``out`` channels) instead of averaging them.
        groups: independent layers side by side (concatenated heads only; see the module doc).

    Parameters are initialised with Glorot's uniform rule (SwinGar Sec. IV), the bias with zeros. Averaged heads:
    ``weight (in, heads * out)``, ``att_dst``/``att_src (heads, out)``; concatenated: ``weight (in, out)``,
    ``att_dst``/``att_src (out,)`` (each channel's attention vector entry, in its head's block).

    Shapes:
        x ``(..., V, in_channels)``, table and valid ``(V, D)`` (:func:`attention_table`) ->
        ``(..., V, out_channels)``.
    """

    def __init__(self, in_channels: int, out_channels: int, heads: int = 1, alpha: float | None = 2.0,
                 activation: str | None = "tanh", norm: str = "graph", centred: bool = False,
                 concat: bool = False, groups: int = 1):
        super().__init__()
        if min(in_channels, out_channels, heads, groups) < 1:
            raise InputError(f"GAT-LN sizes must be >= 1, got in {in_channels}, out {out_channels}, heads {heads}, "
                             f"groups {groups}")
        if alpha is not None and not alpha >= 0:
            raise InputError(f"GAT-LN alpha must be >= 0 (or None for plain GAT), got {alpha}")
        if activation not in ("tanh", None):
            raise InputError(f"GAT-LN activation must be 'tanh' or None, got {activation!r}")
        if norm not in NORMS:
            raise InputError(f"GAT-LN norm must be one of {NORMS}, got {norm!r}")
        if groups > 1 and not concat:
            raise InputError("GAT-LN groups need concatenated heads (concat=True)")
        self.in_channels, self.out_channels, self.heads = in_channels, out_channels, heads
        self.alpha, self.activation, self.norm, self.centred = alpha, activation, norm, bool(centred)
        self.concat, self.groups = bool(concat), groups
        if concat:
            self._head_of = head_columns(out_channels, heads, groups)
            self.weight = nn.Parameter(torch.empty(in_channels, out_channels))
            self.att_dst = nn.Parameter(torch.empty(out_channels))
            self.att_src = nn.Parameter(torch.empty(out_channels))
            # set by reset_parameters (the layer may be built undrawn): (H, out) 1 where the channel belongs to the
            # head; (out,) each channel's place when every head is padded to the widest head's width (heads side by
            # side); (out,) each channel's head
            self.register_buffer("head_mask", torch.empty(heads, out_channels), persistent=False)
            self.register_buffer("padded_index", torch.empty(out_channels, dtype=torch.int64), persistent=False)
            self.register_buffer("head_index", torch.empty(out_channels, dtype=torch.int64), persistent=False)
        else:
            self.weight = nn.Parameter(torch.empty(in_channels, heads * out_channels))
            self.att_dst = nn.Parameter(torch.empty(heads, out_channels))
            self.att_src = nn.Parameter(torch.empty(heads, out_channels))
        self.bias = nn.Parameter(torch.zeros(out_channels))
        self._record: list | None = None
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """Glorot uniform weights (per head for the projection and the attention vectors), zero bias."""
        if self.concat:
            with torch.no_grad():
                self.head_index.copy_(torch.from_numpy(self._head_of))
                self.head_mask.copy_(torch.from_numpy(
                    self._head_of[None] == np.arange(self.heads)[:, None]).to(self.head_mask))
                sizes = np.bincount(self._head_of, minlength=self.heads)
                first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
                self._widest = int(sizes.max())
                self.padded_index.copy_(torch.from_numpy(
                    self._head_of * self._widest + np.arange(self.out_channels) - first[self._head_of]))
            nn.init.uniform_(self.weight, -1.0, 1.0)
            nn.init.uniform_(self.att_dst, -1.0, 1.0)
            nn.init.uniform_(self.att_src, -1.0, 1.0)
            sizes = np.bincount(self._head_of, minlength=self.heads)[self._head_of]  # each channel's head size
            with torch.no_grad():
                self.weight.mul_(math.sqrt(6.0 / (self.in_channels + self.out_channels)))
                att = torch.from_numpy(np.sqrt(6.0 / (1.0 + sizes))).to(self.att_dst)
                self.att_dst.mul_(att)
                self.att_src.mul_(att)
        else:
            bound = math.sqrt(6.0 / (self.in_channels + self.out_channels))
            nn.init.uniform_(self.weight, -bound, bound)
            bound = math.sqrt(6.0 / (1 + self.out_channels))
            nn.init.uniform_(self.att_dst, -bound, bound)
            nn.init.uniform_(self.att_src, -bound, bound)
        nn.init.zeros_(self.bias)

    def extra_repr(self) -> str:
        return (f"{self.in_channels}, {self.out_channels}, heads={self.heads}, alpha={self.alpha}, "
                f"activation={self.activation}, norm={self.norm}, centred={self.centred}, concat={self.concat}, "
                f"groups={self.groups}")

    def score_vectors(self) -> tuple[torch.Tensor, torch.Tensor]:
        """``c_dst, c_src (H, in)``: the score function as linear forms on the input features."""
        if self.concat:
            return (self.head_mask * self.att_dst) @ self.weight.T, (self.head_mask * self.att_src) @ self.weight.T
        W = self.weight.view(self.in_channels, self.heads, self.out_channels)
        return torch.einsum("chk,hk->hc", W, self.att_dst), torch.einsum("chk,hk->hc", W, self.att_src)

    def projection(self) -> torch.Tensor:
        """``(H * in, out)``: the heads' stacked projections, applied to the per-head aggregates ``(H, in)``
        flattened (averaged heads: each head's full projection over ``H``; concatenated: zero outside its block)."""
        if self.concat:
            return (self.head_mask[:, None, :] * self.weight[None]).reshape(self.heads * self.in_channels, -1)
        W = self.weight.view(self.in_channels, self.heads, self.out_channels).transpose(0, 1)
        return W.reshape(self.heads * self.in_channels, self.out_channels) / self.heads

    def attention(self, x: torch.Tensor, table: torch.Tensor, valid: torch.Tensor,
                  gathered: torch.Tensor | None = None) -> torch.Tensor:
        """Attention weights ``P (B, V, D, H)`` (rows sum to 1 over the valid slots) of ``x (B, V, in)``;
        ``gathered``: ``x`` at the table's slots ``(B, V, D, in)`` when already computed.

        ``P`` is a view of a ``(B, V, H, D)`` tensor: the scores are laid out with the slots last, where the row norms
        and the softmax run over contiguous memory. Without autograd the score passes run in place (SwinGar's
        streaming frame on the CPU spends most of its time in passes over these ``V D H`` scores). Every step has
        shapes fixed by the table (no data-dependent indexing, no host synchronisation), so the layer can be captured
        in a CUDA graph."""
        c_dst, c_src = self.score_vectors()
        inplace = not torch.is_grad_enabled()
        slots = valid[None, :, None, :]  # (1, V, 1, D)
        mu = None
        # the linear score function g of SwinGar Eq. 2, per head and edge j -> i
        if self.centred:
            mu = neighbourhood_mean(x, table, valid, gathered)
            # c . (x_j - mu_i): the scores of the centred features (the projections are linear)
            s = gather_slots(x @ c_src.T, table)  # (B, V, H, D): c_src . x_j
            centre = ((x - mu) @ c_dst.T - mu @ c_src.T)[..., None]  # (B, V, H, 1)
            s = s.add_(centre) if inplace else s + centre
        else:
            H = c_dst.shape[0]
            u = x @ torch.cat([c_dst, c_src]).T  # (B, V, 2H)
            s = gather_slots(u[..., H:].contiguous(), table)
            s = s.add_(u[..., :H, None]) if inplace else s + u[..., :H, None]
        if self.alpha is not None:
            s = s.masked_fill_(~slots, 0.0) if inplace else s * slots
            # norms clamped away from 0: the square root's gradient there is infinite (a zero recurrent state)
            rows = torch.linalg.vector_norm(s, dim=-1).clamp_min(NORM_EPS)  # (B, V, H): each vertex's score row norm
            if self.norm == "row":  # every row's norm becomes alpha
                norm = rows
            else:
                norm = self._bound(x, rows, lipschitz(c_dst, c_src), table, valid, gathered, mu, inplace)
            scale = (self.alpha / norm)[..., None]  # SwinGar Eq. 4: (B, V or 1, H, 1)
            s = s.mul_(scale) if inplace else s * scale
        s = nn.functional.leaky_relu_(s, SCORE_SLOPE) if inplace else nn.functional.leaky_relu(s, SCORE_SLOPE)
        bounded = self.alpha is not None and self.alpha <= MAX_BOUNDED_ALPHA
        return slot_softmax(s, slots, bounded, inplace).transpose(2, 3)  # SwinGar Eq. 2's softmax

    def _bound(self, x: torch.Tensor, rows: torch.Tensor, lip: torch.Tensor, table: torch.Tensor,
               valid: torch.Tensor, gathered: torch.Tensor | None, mu: torch.Tensor | None,
               inplace: bool) -> torch.Tensor:
        """Eq. 4's normaliser ``(B, V or 1, H)``: the larger of the score rows' norms ``rows (B, V, H)`` and the
        feature bound ``max ||x_j|| * lip`` (``lip (H,)``), per vertex (``norm="node"``) or per graph; ``mu (B, V,
        in)``: the neighbourhood means (centred scores)."""
        if self.centred and gathered is not None:
            # ||x_j - mu_i|| read off the gathered features without writing their differences (the clamp keeps
            # the norms off 0, where the square root's gradient is infinite)
            B, V, D, C = gathered.shape
            feats = torch.cdist(gathered.reshape(B * V, D, C), mu.reshape(B * V, 1, C),
                                compute_mode="donot_use_mm_for_euclid_dist").view(B, V, D).clamp_min(NORM_EPS)
        elif self.centred:  # slot by slot: each slot's neighbours gathered and measured, no (B, V, D, in) tensor
            feats = centred_norms(x, mu, table, inplace).clamp_min(NORM_EPS)
        else:
            feats = x.square().sum(-1).clamp_min(NORM_EPS * NORM_EPS).sqrt()[:, table]  # (B, V, D) ||x_j||
        feat = feats.masked_fill(~valid[None], 0.0).amax(2)  # (B, V): largest over the neighbourhood
        if self.norm == "graph":
            rows, feat = rows.amax(1, keepdim=True), feat.amax(1, keepdim=True)  # (B, 1, H), (B, 1)
        return torch.maximum(rows, feat[..., None] * lip)  # SwinGar Eq. 4's denominator

    def _native_applies(self, x: torch.Tensor) -> bool:
        """Whether the fused CPU kernel computes this call: the default design (concatenated heads, centred scores,
        per-node norm, bounded scores), no attention recorded, and
        :func:`~loosefit.models.layers.gat_ln_fast.native_applies`."""
        default = (self.concat and self.centred and self.norm == "node" and self.alpha is not None
                   and self.alpha <= MAX_BOUNDED_ALPHA)
        return default and self._record is None and fast.native_applies(x, self.weight)

    def _native_forward(self, x: torch.Tensor, table: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """The layer on ``x (B, V, in)`` through the fused CPU kernel: the products here, the neighbourhood means,
        the attention and the aggregation in one sweep there (:func:`~loosefit.models.layers.gat_ln_fast.native_forward`
        checks the table first)."""
        with torch.no_grad():
            c_dst, c_src = self.score_vectors()
            return fast.native_forward(
                x, x @ self.weight, x @ torch.cat([c_dst, c_src]).T, lipschitz(c_dst, c_src), table, valid,
                self.head_index, self.bias, self.activation == "tanh", self.alpha, SCORE_SLOPE, NORM_EPS)

    def forward(self, x: torch.Tensor, table: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        """``x (..., V, in)``, ``table``/``valid (V, D)`` from :func:`attention_table` -> ``(..., V, out)``."""
        if x.shape[-1] != self.in_channels or x.shape[-2] != table.shape[0]:
            raise InputError(f"GAT-LN expects (..., {table.shape[0]}, {self.in_channels}) features, got {tuple(x.shape)}")
        lead = x.shape[:-2]
        x = x.reshape(-1, *x.shape[-2:])
        if self._native_applies(x):
            return self._native_forward(x, table, valid).reshape(*lead, x.shape[-2], self.out_channels)
        # concatenated heads project before they aggregate where that is faster (gat_ln_fast.projects_first)
        first = self.concat and fast.projects_first(self.heads, x.device)
        gathered = None if first else x.index_select(1, table.reshape(-1)).unflatten(1, table.shape)  # (B, V, D, in)
        P = self.attention(x, table, valid, gathered)  # (B, V, D, H)
        if self._record is not None:
            self._record.append(tuple(float(v) for v in attention_entropy(P.detach(), valid)))
        if first:
            out = fast.project_then_sum(x, self.weight, self.padded_index, self._widest, table, P)
            out = out + self.bias if torch.is_grad_enabled() else out.add_(self.bias)
        else:
            # sum_j P_ijh W_h x_j = W_h (sum_j P_ijh x_j) (SwinGar Eq. 2's aggregation): aggregate the inputs per
            # head, then one product with the heads' stacked projections (averaged heads: H * out columns, all used)
            z = torch.einsum("bvdh,bvdc->bvhc", P, gathered)  # (B, V, H, in)
            out = z.flatten(-2) @ self.projection() + self.bias
        if self.activation == "tanh":
            out = torch.tanh(out) if torch.is_grad_enabled() else out.tanh_()
        return out.reshape(*lead, *out.shape[-2:])


@contextlib.contextmanager
def recording_attention(module: nn.Module):
    """While active, every :class:`GATLN` inside ``module`` records its attention entropy on each call: yields
    ``{layer name: [(entropy, uniform entropy), ...]}`` (nats, means over batch, vertices and heads; see
    :func:`attention_entropy`), one pair per call."""
    layers = {name: m for name, m in module.named_modules() if isinstance(m, GATLN)}
    log: dict[str, list] = {name: [] for name in layers}
    for name, m in layers.items():
        m._record = log[name]
    try:
        yield log
    finally:
        for m in layers.values():
            m._record = None
