"""How the GAT-LN layer (:mod:`loosefit.models.layers.gat_ln`) runs fast: its passes over the attention table, the
aggregation of concatenated heads, and the dispatch to the fused CPU kernel (:mod:`loosefit.models.layers.native`).
Each function computes what the layer's equations say; the choices here only decide how.

The graph is a padded neighbour table (:func:`~loosefit.models.layers.gat_ln.attention_table`) rather than PyG's
edge list: the forward pass then scatters nothing (the backward pass scatters one value per vertex, slot and input
channel), which matters on CPUs where torch's scatter is slow with several threads. Averaged heads: since ``sum_j
P_ij W_h x_j = W_h sum_j P_ij x_j``, the inputs are aggregated per head first and projected once by all heads'
stacked weights: the neighbour gather moves ``in`` channels instead of ``heads * out`` (SwinGar at the paper's sizes
on a 2.8k-vertex dress, one CPU thread: 2.7 s a frame the other way round, 0.2 s this way). Concatenated heads:
every output channel belongs to one head, so the inputs are projected once (``in -> out``) and the projections
gathered and weighted by their channel's head; the stacked product would multiply ``heads - 1`` zeros for every
weight (SwinGar's streaming frame, 9k vertices, one CPU thread: see ``benchmarks/experiments/LOG.md``). Every shape in the
forward pass is fixed by the table, with no data-dependent indexing or host synchronisation, so a layer can be
captured in a CUDA graph (:mod:`loosefit.models.cuda_graph`).

On the CPU without autograd (inference), the default design (per-node norm, centred scores, concatenated heads) in
float32 runs through a fused C kernel (:mod:`loosefit.models.layers.native`): the products in
:class:`~loosefit.models.layers.gat_ln.GATLN`, then the neighbourhood means, the scores, their normalisation, the
softmax, the aggregation, the bias and the tanh in one sweep over the vertices. The eager passes write and read the
``(B, V, H, D)`` scores about ten times; at SwinGar's sizes on a 9k-vertex dress the kernel halves the streaming
frame (``benchmarks/README.md``). Training, other devices, float64, the other designs and
:func:`~loosefit.models.layers.gat_ln.recording_attention` keep the eager layer.
"""

from __future__ import annotations

import weakref

import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.models.layers import native

#: Off the CPU, concatenated heads above this count project before aggregating (see the module doc): with few
#: heads the per-head aggregates are small and one stacked product is cheaper than a gather per slot. On the CPU
#: every concatenated layer projects first (:func:`neighbour_sum`'s one ``embedding_bag`` is faster either way).
PROJECT_FIRST_HEADS = 4
#: On the CPU every concatenated layer projects first and :func:`neighbour_sum` runs as one ``embedding_bag``.
CPU_EMBEDDING_BAG = True
#: How many :func:`bag_rows` indices the CPU keeps (tables, batch sizes and head counts together).
BAG_ROWS_KEPT = 32
_BAG_ROWS: dict = {}


def bag_rows(table: torch.Tensor, batch: int, heads: int) -> torch.Tensor:
    """``rows (B, V, H, D)`` int64: ``(b V + table[v, d]) H + h``, the row of ``(b, table[v, d], h)`` in a ``(B, V, H,
    ...)`` tensor flattened over its first three axes. On the CPU it is kept per table (while that tensor lives and
    is not modified), batch and head count: building it took a tenth of a concatenated layer's time at SwinGar's
    sizes, and a garment's table does not change."""
    key = (id(table), table.device, batch, heads)
    hit = _BAG_ROWS.get(key)
    if hit is not None and hit[0]() is table and hit[1] == table._version:
        return hit[2]
    V = table.shape[0]
    rows = ((torch.arange(batch, device=table.device)[:, None, None, None] * V + table[None, :, None, :]) * heads
            + torch.arange(heads, device=table.device)[None, None, :, None])
    if table.device.type == "cpu" and not torch.compiler.is_compiling():
        while len(_BAG_ROWS) >= BAG_ROWS_KEPT:
            _BAG_ROWS.pop(next(iter(_BAG_ROWS)))  # the oldest first
        _BAG_ROWS[key] = (weakref.ref(table, lambda _, key=key: _BAG_ROWS.pop(key, None)), table._version, rows)
    return rows


def gather_slots(u: torch.Tensor, table: torch.Tensor) -> torch.Tensor:
    """``out[b, v, h, d] = u[b, table[v, d], h]``: per-vertex, per-head values ``u (B, V, H)`` at the table's slots ->
    ``(B, V, H, D)`` (the slots last, as the attention's passes read them)."""
    B, V, H = u.shape
    return u.index_select(1, table.reshape(-1)).view(B, V, -1, H).transpose(2, 3).contiguous()


def neighbourhood_mean(x: torch.Tensor, table: torch.Tensor, valid: torch.Tensor,
                       gathered: torch.Tensor | None = None) -> torch.Tensor:
    """``mu (B, V, C)``: the mean of ``x (B, V, C)`` over each vertex's valid slots (itself and its neighbours); read
    off ``gathered`` (``x`` at the slots, ``(B, V, D, C)``) when there is one (a batched product), else as a
    neighbour sum (no ``(B, V, D, C)`` tensor)."""
    weight = valid.to(x.dtype) / valid.sum(1, keepdim=True).to(x.dtype)  # (V, D)
    if gathered is not None:
        return (weight[None, :, None, :] @ gathered)[:, :, 0]
    B, V, D = x.shape[0], x.shape[1], table.shape[1]
    return neighbour_sum(x[:, :, None], table, weight[None, :, :, None].expand(B, V, D, 1))[:, :, 0]


def centred_norms(x: torch.Tensor, mu: torch.Tensor, table: torch.Tensor, inplace: bool) -> torch.Tensor:
    """``out[b, v, d] = ||x[b, table[v, d]] - mu[b, v]||``: features ``x (B, V, C)`` at the table's slots, less a
    per-vertex centre ``mu (B, V, C)`` -> ``(B, V, D)``, slot by slot (no ``(B, V, D, C)`` tensor). ``inplace`` (no
    autograd): every slot in one reused buffer; a fresh ``(B, V, C)`` tensor per slot and pass made this ten times
    slower at SwinGar's 256 channels (9k vertices, one CPU thread)."""
    columns = table.T.contiguous()
    if not inplace:
        return torch.stack([torch.linalg.vector_norm(x.index_select(1, c) - mu, dim=-1) for c in columns], 2)
    buffer, out = torch.empty_like(x), x.new_empty(*x.shape[:2], len(columns))
    for d, c in enumerate(columns):
        torch.linalg.vector_norm(torch.index_select(x, 1, c, out=buffer).sub_(mu), dim=-1, out=out[..., d])
    return out


def slot_softmax(s: torch.Tensor, slots: torch.Tensor, bounded: bool, inplace: bool) -> torch.Tensor:
    """The softmax of scores ``s (B, V, H, D)`` over their last axis (the table's slots), zero where ``slots (1, V,
    1, D)`` is False. Written out because torch's CPU softmax over a short last axis is ~15x slower than these
    passes (SwinGar, 9k vertices, 10 slots: 37 ms against 4). ``bounded``: the scores lie in ``[-alpha, alpha]``
    (GAT-LN), so no maximum is subtracted first; ``inplace``: overwrite ``s`` (no autograd)."""
    if not bounded:  # a padded slot holds the vertex's own score: a finite shift like any other
        s = s.sub_(s.amax(-1, keepdim=True)) if inplace else s - s.amax(-1, keepdim=True)
    e = s.exp_().masked_fill_(~slots, 0.0) if inplace else s.exp().masked_fill(~slots, 0.0)
    return e.div_(e.sum(-1, keepdim=True)) if inplace else e / e.sum(-1, keepdim=True)


def neighbour_sum(y: torch.Tensor, table: torch.Tensor, P: torch.Tensor) -> torch.Tensor:
    """``out[b, v, h] = sum_d P[b, v, d, h] y[b, table[v, d], h]``: each head's features ``y (B, V, H, C)`` summed
    over the table's slots (``table (V, D)``) with that head's weights ``P (B, V, D, H)`` -> ``(B, V, H, C)``.

    On the CPU one ``embedding_bag`` per call (a bag per vertex and head, its slots' rows weighted: no gathered
    ``(B, V, D, H, C)`` tensor and no temporary per slot; 4-11 times faster than the loop below on SwinGar's
    layers, one thread; ``P`` is read without a copy where it is a view of a ``(B, V, H, D)`` tensor, as
    :meth:`~loosefit.models.layers.gat_ln.GATLN.attention` returns it); elsewhere the slots one by one (the
    shapes fixed by the table, for CUDA graphs)."""
    B, V, H, C = y.shape
    D = table.shape[1]
    if y.device.type == "cpu" and CPU_EMBEDDING_BAG:
        weights = P.permute(0, 1, 3, 2).reshape(B * V * H, D)
        out = nn.functional.embedding_bag(bag_rows(table, B, H).view(B * V * H, D), y.reshape(B * V * H, C),
                                          per_sample_weights=weights, mode="sum")
        return out.view(B, V, H, C)
    return neighbour_sum_by_slot(y, table, P)


def neighbour_sum_by_slot(y: torch.Tensor, table: torch.Tensor, P: torch.Tensor) -> torch.Tensor:
    """:func:`neighbour_sum` slot by slot, on any device: one gather and one multiply-add per slot, no
    ``(B, V, D, H, C)`` tensor written."""
    B, V, H, C = y.shape
    columns = table.T.contiguous()
    acc = y.new_zeros(B, V, H, C)
    for d in range(table.shape[1]):
        acc.addcmul_(P[:, :, d, :, None], y.index_select(1, columns[d]).view(B, V, H, C))
    return acc


def projects_first(heads: int, device: torch.device) -> bool:
    """Whether a layer of ``heads`` concatenated heads projects its inputs before aggregating them
    (:func:`project_then_sum`) rather than aggregating them per head first: on the CPU always (with
    :data:`CPU_EMBEDDING_BAG`), elsewhere above :data:`PROJECT_FIRST_HEADS` heads."""
    return heads > PROJECT_FIRST_HEADS or (CPU_EMBEDDING_BAG and device.type == "cpu")


def project_then_sum(x: torch.Tensor, weight: torch.Tensor, padded_index: torch.Tensor, widest: int,
                     table: torch.Tensor, P: torch.Tensor) -> torch.Tensor:
    """Concatenated heads' aggregation ``out[b, v, c] = sum_d P[b, v, d, head(c)] (x W)[b, table[v, d], c]`` ->
    ``(B, V, out)`` (no bias), for ``x (B, V, in)``, ``weight (in, out)``, attention ``P (B, V, D, H)``.

    Each output channel belongs to one head: the inputs are projected once (``in -> out``), then the neighbours'
    projections are added up slot by slot, each channel weighted by its head's attention (the stacked product
    would multiply ``H - 1`` zeros for every weight; no ``(B, V, D, out)`` tensor is written). ``padded_index
    (out,)``: each channel's place when every head is padded to ``widest`` channels."""
    B, V, H = x.shape[0], x.shape[1], P.shape[-1]
    out_channels = weight.shape[1]
    # heads padded to equal widths (zero columns), so that a head's weight broadcasts over its channels
    padded = weight.new_zeros(weight.shape[0], H * widest).index_copy(1, padded_index, weight)
    y = x @ padded  # (B, V, H * widest)
    out = neighbour_sum(y.view(B, V, H, widest), table, P).flatten(-2)  # SwinGar Eq. 2's aggregation
    if H * widest != out_channels:  # drop the padding (a gather: index_select on the last axis is ~10x slower)
        out = torch.gather(out, -1, padded_index.expand(B, V, -1))
    return out


def native_applies(x: torch.Tensor, weight: torch.Tensor) -> bool:
    """Whether the fused CPU kernel can compute a layer of the default design on ``x (B, V, in)``: float32 on the
    CPU, the kernel built and switched on, no gradient wanted (of ``x`` or of the layer's ``weight``) and no
    ``torch.compile`` tracing."""
    if not (x.device.type == "cpu" and x.dtype == torch.float32 and native.enabled()):
        return False
    if torch.is_grad_enabled() and (x.requires_grad or weight.requires_grad):
        return False
    return not torch.compiler.is_compiling() and native.library() is not None


def native_forward(x: torch.Tensor, y: torch.Tensor, u: torch.Tensor, lip: torch.Tensor, table: torch.Tensor,
                   valid: torch.Tensor, head_of: torch.Tensor, bias: torch.Tensor, tanh: bool, alpha: float,
                   slope: float, eps: float) -> torch.Tensor:
    """A layer's output ``(B, V, out)`` through the fused CPU kernel (arguments as
    :func:`loosefit.models.layers.native.gat_ln_concat_node_centred` takes them), after checking the table: the
    kernel reads it without bounds checks."""
    if table.numel() and (int(table.min()) < 0 or int(table.max()) >= x.shape[1]):
        raise InputError(f"the attention table indexes vertices outside [0, {x.shape[1]})")
    if not bool(valid[:, 0].all()):
        raise InputError("the attention table's first slot (each vertex itself) must be valid")
    return native.gat_ln_concat_node_centred(x, y, u, lip, table, valid, head_of, bias, tanh, alpha, slope, eps)
