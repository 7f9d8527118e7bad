"""FitGar frame by frame on one garment graph, with shapes fixed once: the step a CUDA graph captures.

:meth:`loosefit.models.fitgar.FitGar.forward` rebuilds its graphs every call: PyG's ``GATConv`` removes and adds
self loops (boolean indexing: a host synchronisation on a GPU) and scatters its messages, and the edge-contraction
pooling matches edges on the host (:func:`~loosefit.models.layers.edge_pool.greedy_contraction`). Here the
garment's graph (a collated batch's ``edge_index``, ``faces`` and ``batch``, the same every frame) is turned
once into padded neighbour tables (:func:`~loosefit.models.layers.gat_block.incoming_table`), and every frame
runs :meth:`~loosefit.models.layers.gat_block.GATBlock.forward_table` and
:meth:`~loosefit.models.layers.edge_pool.EdgeContractionPooling.forward_static`: the same network, the same
parameters, outputs equal to the eager pass's to float round-off.

On CUDA with autograd off, :class:`FitGarStream` captures the step once per input shape
(:mod:`loosefit.models.cuda_graph`) and replays it. The pooling's matching runs a fixed number of rounds there
(:data:`GRAPH_ROUNDS`); a frame whose matching needs more is computed again eagerly (its ``exact`` flag, read
after the replay, says so), so the outputs never depend on the round count.
"""

from __future__ import annotations

import torch

from loosefit.errors import InputError
from loosefit.geometry.normals import vertex_normals_torch
from loosefit.models.cuda_graph import capture_or_none, clone_outputs, graphs_enabled
from loosefit.models.layers.gat_block import incoming_table

#: The per-frame inputs of a collated batch (:func:`~loosefit.models.fitgar_data.collate_frames`), in order.
FRAME_INPUTS = ("anchor", "body_normal", "body_rel", "garment_rel", "alpha", "shape", "pose", "joints")
#: Matching rounds of the captured pooling (each takes every locally first edge). FitGar at the paper's sizes
#: (untrained) on a 3,648-vertex dress needed 6 to 11 (three frames, two poolings each: 21,438 edges; measured on
#: the CPU); a frame that needs more is recomputed eagerly.
GRAPH_ROUNDS = 32


class FitGarStream:
    """A FitGar (eval mode) bound to the graph of ``batch`` (a :func:`~loosefit.models.fitgar_data.collate_frames`
    batch: one frame or several of one garment-body pair), predicting frames of that graph.

    ``stream(batch)`` -> :meth:`FitGar.forward`'s outputs for a batch of the same garments (only the per-frame
    inputs :data:`FRAME_INPUTS` are read from it). ``use_graphs``: capture and replay on CUDA with autograd off.
    :meth:`FitGar.forward` streams through one automatically there.
    """

    def __init__(self, model, batch: dict, use_graphs: bool = True):
        model.check_anchor(batch)  # the anchors belong to the garment: checked once
        self.model, self.use_graphs = model, use_graphs
        edge_index = batch["edge_index"]
        self.num_nodes = N = batch["anchor"].shape[0]
        table, valid = incoming_table(edge_index.cpu().numpy(), N)
        device = batch["anchor"].device
        self.table, self.valid = torch.from_numpy(table).to(device), torch.from_numpy(valid).to(device)
        # a cluster of two nodes has at most both their neighbourhoods: the pooled table always fits
        self.pool_width = 2 * table.shape[1] - 1
        self.edge_index, self.faces, self.index = edge_index, batch["faces"], batch["batch"]
        self._graph = None
        self._captured_shapes = None

    def matches(self, batch: dict) -> bool:
        """Whether ``batch`` is of this stream's garment graph (compares the topology: a host synchronisation)."""
        return (batch["anchor"].shape[0] == self.num_nodes and batch["edge_index"].shape == self.edge_index.shape
                and batch["faces"].shape == self.faces.shape and batch["edge_index"].device == self.edge_index.device
                and bool(torch.equal(batch["edge_index"], self.edge_index))
                and bool(torch.equal(batch["faces"], self.faces)) and bool(torch.equal(batch["batch"], self.index)))

    # ------------------------------------------------------------------ the step

    def _branch(self, branch, x: torch.Tensor, rounds: int | None, exact: list) -> torch.Tensor:
        table, valid, info = self.table, self.valid, None
        for k, block in enumerate(branch.blocks):
            if k == branch.pool_before:
                x, table, valid, info, ok = branch.pool.forward_static(x, self.edge_index, self.pool_width, rounds)
                exact.append(ok)
            if k == branch.unpool_before:
                x, table, valid = branch.pool.unpool(x, info), self.table, self.valid
            x = branch.activation(block.forward_table(x, table, valid))
        return x

    def _generator(self, gen, x: torch.Tensor, rounds: int | None, exact: list) -> torch.Tensor:
        if gen.magnitude is None:
            return gen.output(self._branch(gen.direction, x, rounds, exact))["displacement"]
        return gen.output(self._branch(gen.magnitude, x, rounds, exact),
                          self._branch(gen.direction, x, rounds, exact))["displacement"]

    def step(self, anchor, body_normal, body_rel, garment_rel, alpha, shape, pose, joints,
             rounds: int | None = None) -> dict:
        """One pass on the per-frame inputs (:data:`FRAME_INPUTS`, shapes as in the collated batch): FitGar's
        outputs and ``exact ()`` bool (False when the pooling's matching did not finish in ``rounds``; None:
        run until it does)."""
        m, c, idx = self.model, self.model.config, self.index
        frame = {"alpha": alpha, "shape": shape, "pose": pose}
        exact: list = []
        if m.coarse is None:
            coarse_disp = torch.zeros_like(anchor)
        else:
            a1 = ((alpha[:, :1] - m.alpha_mean[:1]) / m.alpha_std[:1])[idx]
            x = torch.cat([body_normal, (body_rel - m.rel_mean) / m.rel_std, a1], -1)
            h = torch.tanh(m.coarse_first.forward_table(x, self.table, self.valid))
            coarse_disp = self._generator(m.coarse, h, rounds, exact)
        coarse = anchor + coarse_disp  # FitGar Eq. 5
        dist = (coarse[:, None] - joints[idx]).norm(dim=-1)
        parts = [vertex_normals_torch(coarse, self.faces), (garment_rel - m.rel_mean) / m.rel_std,
                 (dist - m.dist_mean) / m.dist_std]
        if c.parser_mode == "nodes":
            parts.append(m.attributes(frame)[idx])
        h = torch.tanh(m.detail_first.forward_table(torch.cat(parts, -1), self.table, self.valid))
        if c.parser_mode == "multiply":
            h = h * m.encoding(frame)[idx]  # FitGar Eq. 7
        elif c.parser_mode == "concat":
            h = torch.cat([h, m.encoding(frame)[idx]], -1)
        detail_disp = self._generator(m.detail, h, rounds, exact)
        ok = torch.stack(exact).all() if exact else torch.ones((), dtype=torch.bool, device=anchor.device)
        return {"coarse": coarse, "verts": coarse + detail_disp,  # FitGar Eq. 9
                "coarse_displacement": coarse_disp, "detail_displacement": detail_disp, "exact": ok}

    def _captured(self, *inputs: torch.Tensor) -> dict:
        return self.step(*inputs, rounds=GRAPH_ROUNDS)

    def __call__(self, batch: dict) -> dict:
        missing = [k for k in FRAME_INPUTS if k not in batch]
        if missing:
            raise InputError(f"FitGar frames lack {missing}")
        inputs = [batch[k] for k in FRAME_INPUTS]
        if self.use_graphs and graphs_enabled(inputs[0].device):
            shapes = [(t.shape, t.dtype) for t in inputs]
            if self._captured_shapes != shapes:
                self._captured_shapes = shapes
                self._graph = capture_or_none(self._captured, inputs, "FitGar frame")
            if self._graph is not None:
                out = clone_outputs(self._graph(*inputs))
                if bool(out.pop("exact")):
                    return out
        out = self.step(*inputs)
        out.pop("exact")
        return out
