"""The streaming steps that CUDA graphs capture: GAT-LN's project-first aggregation, FitGar over fixed tables and
the static edge pooling equal the eager implementations (on a GPU, graph replay against eager streaming:
``test_cuda_graphs.py``)."""

from __future__ import annotations

import copy
import numpy as np
import pytest
import torch

from loosefit.models.fitgar import FitGar
from loosefit.models.fitgar_data import collate_frames
from loosefit.models.fitgar_stream import FRAME_INPUTS, GRAPH_ROUNDS, FitGarStream
from loosefit.models.layers import gat_ln_fast
from loosefit.models.layers.edge_pool import EdgeContractionPooling, greedy_contraction, greedy_contraction_rounds
from loosefit.models.layers.gat_block import GATBlock, incoming_table
from loosefit.models.layers.gat_ln import GATLN, attention_table
from loosefit.models.swingar import BoundSwinGar, SwinGar, SwinGarConfig

from .fitgar_fixtures import TINY, make_frames, set_stats
from .layers.test_gat_ln_designs import FACES, IN, OUT, V, by_hand
from .test_fitgar import SIZES
from .test_swingar import SMALL, data, store  # noqa: F401  (fixtures)

#: SwinGar with more heads than GAT-LN aggregates before projecting, so both aggregations run.
MANY_HEADS = SwinGarConfig(**{**SMALL, "graph_heads": [6, 6], "state_heads": 6, "corrective_heads": 2})


@pytest.mark.parametrize("heads, norm, centred", [(6, "node", True), (8, "graph", False), (5, "node", False)])
def test_project_first_heads_are_the_layer_by_hand(heads, norm, centred):
    """Concatenated heads project first (on the CPU always, elsewhere past PROJECT_FIRST_HEADS): the same layer as
    written out by hand (float64), as the stacked product computes it and as the slot-by-slot sum of CUDA does."""
    assert heads > gat_ln_fast.PROJECT_FIRST_HEADS
    torch.manual_seed(0)
    layer = GATLN(IN, 2 * OUT + 1, heads=heads, alpha=2.0, norm=norm, centred=centred, concat=True).double()
    with torch.no_grad():
        layer.bias.normal_()
    table, valid = map(torch.from_numpy, attention_table(FACES, V))
    x = torch.randn(3, V, IN, generator=torch.Generator().manual_seed(1), dtype=torch.float64) * 2.0 + 1.0
    got = layer(x, table, valid)
    torch.testing.assert_close(got[1], by_hand(layer, x[1]), rtol=1e-10, atol=1e-12)
    before = gat_ln_fast.PROJECT_FIRST_HEADS, gat_ln_fast.CPU_EMBEDDING_BAG
    try:
        gat_ln_fast.CPU_EMBEDDING_BAG = False  # the slot-by-slot sum of CUDA
        by_slot = layer(x, table, valid)
        gat_ln_fast.PROJECT_FIRST_HEADS = 10 ** 6  # the stacked product, as the layer was first written
        stacked = layer(x, table, valid)
    finally:
        gat_ln_fast.PROJECT_FIRST_HEADS, gat_ln_fast.CPU_EMBEDDING_BAG = before
    torch.testing.assert_close(got, stacked, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(got, by_slot, rtol=1e-12, atol=1e-12)


def test_neighbour_sums_and_their_gradients_agree():
    """embedding_bag (CPU) and slot by slot (CUDA) against the gathered sum written out, values and gradients."""
    g = torch.Generator().manual_seed(0)
    table = torch.randint(0, 30, (30, 5), generator=g)
    y = torch.randn(2, 30, 3, 4, generator=g, dtype=torch.float64, requires_grad=True)
    P = torch.rand(2, 30, 5, 3, generator=g, dtype=torch.float64, requires_grad=True)
    written = (P[..., None] * y[:, table]).sum(2)  # (B, V, D, H, C) summed over the slots
    up = torch.randn_like(written)
    expected = torch.autograd.grad(written, (y, P), up)
    for fn in (gat_ln_fast.neighbour_sum, gat_ln_fast.neighbour_sum_by_slot):
        out = fn(y, table, P)
        torch.testing.assert_close(out, written, rtol=1e-12, atol=1e-12)
        for got, want in zip(torch.autograd.grad(out, (y, P), up), expected):
            torch.testing.assert_close(got, want, rtol=1e-12, atol=1e-12)


def test_swingar_stream_step_keeps_the_state_in_place(data):  # noqa: F811
    """The step a CUDA graph captures writes the next state into the state's own tensors and returns the
    eager call's outputs; the eager frames equal the whole sequence in one call."""
    torch.manual_seed(0)
    bound = BoundSwinGar(SwinGar.from_data(data, MANY_HEADS).eval(), data.graphs[0])
    s = data.sequences[0].sequences[0]
    root, joints = torch.from_numpy(s.root[None, :6]), torch.from_numpy(s.joints[None, :6])
    with torch.no_grad():
        whole = bound(root, joints)
        state = bound(root[:, :1], joints[:, :1])["state"]
        static = [t.clone() for t in (state["root"], state["joints"], state["gates"])]
        for t in range(1, 6):
            eager = bound(root[:, t:t + 1], joints[:, t:t + 1], state)
            step = bound.stream_step(root[:, t:t + 1], joints[:, t:t + 1], *static)
            for k in ("verts", "coarse", "weights", "correction"):
                assert torch.equal(step[k], eager[k]), k
            for got, key in zip(static, ("root", "joints", "gates")):
                assert torch.equal(got, eager["state"][key]), key
            torch.testing.assert_close(eager["verts"][:, 0], whole["verts"][:, t], rtol=1e-5, atol=1e-6)
            state = eager["state"]


def test_incoming_table_is_gatconv_neighbourhood():
    edge_index = np.array([[2, 1, 0, 3, 2, 1], [0, 0, 1, 1, 1, 1]])  # node 1 has a self loop
    table, valid = incoming_table(edge_index, 4)
    assert table[0][valid[0]].tolist() == [2, 1, 0]  # in the edge list's order, itself last
    assert table[1][valid[1]].tolist() == [0, 3, 2, 1]
    assert table[2][valid[2]].tolist() == [2] and table[3][valid[3]].tolist() == [3]
    table, valid = incoming_table(np.array([[1, 1], [0, 0]]), 2)
    assert table[0][valid[0]].tolist() == [1, 1, 0]  # repeated edges count twice, as in GATConv


def test_gat_block_over_a_table_is_the_edge_list_block():
    torch.manual_seed(0)
    block = GATBlock.of_width(5, 12, heads=2).eval()
    rng = np.random.default_rng(0)
    e = rng.integers(0, 40, (2, 150))
    e = np.unique(np.concatenate([e, e[::-1]], 1), axis=1)
    x = torch.randn(40, 5)
    table, valid = map(torch.from_numpy, incoming_table(e, 40))
    with torch.no_grad():  # one thread (tests/models/conftest.py): GATConv's own sums, to the bit
        assert torch.equal(block.forward_table(x, table, valid), block(x, torch.from_numpy(e)))


def test_matching_in_rounds_is_the_greedy_matching():
    """Random graphs with ties: the rounds give greedy_contraction's clusters, and too few rounds say so."""
    for seed in range(5):
        g = torch.Generator().manual_seed(seed)
        e = torch.randint(0, 60, (2, 300), generator=g)
        score = torch.randint(0, 20, (300,), generator=g).float()  # many ties: argsort's order decides
        cluster, taken = greedy_contraction(e, score, 60)
        got, got_taken, done = greedy_contraction_rounds(e, score, 60)
        assert bool(done) and torch.equal(got, cluster)
        assert sorted(torch.nonzero(got_taken)[:, 0].tolist()) == sorted(taken.tolist())
    assert not bool(greedy_contraction_rounds(e, score, 60, rounds=1)[2])


def test_static_pooling_is_the_pooling():
    torch.manual_seed(0)
    pool = EdgeContractionPooling(4)
    rng = np.random.default_rng(1)
    e = rng.integers(0, 30, (2, 80))
    e = torch.from_numpy(np.unique(np.concatenate([e, e[::-1]], 1), axis=1))
    x = torch.randn(30, 4)
    pooled, edges, _, info = pool(x, e, torch.zeros(30, dtype=torch.long))
    width = 2 * incoming_table(e.numpy(), 30)[0].shape[1] - 1
    s_pooled, table, valid, s_info, exact = pool.forward_static(x, e, width, rounds=30)
    n = len(pooled)
    assert bool(exact) and torch.equal(s_info.cluster, info.cluster)
    torch.testing.assert_close(s_pooled[:n], pooled)
    assert (s_pooled[n:] == 0).all()
    ref_table, ref_valid = incoming_table(edges.numpy(), n, width)
    assert np.array_equal(table[:n].numpy(), ref_table) and np.array_equal(valid[:n].numpy(), ref_valid)
    y = torch.randn(30, 3)
    torch.testing.assert_close(pool.unpool(y, s_info), pool.unpool(y[:n], info))


@pytest.fixture(scope="module")
def fitgar_frames(body):
    from loosefit.garment import make_garment
    from loosefit.motion.procedural import generate

    dress = make_garment("dress", body, seed=0, edge_length=0.06)
    _, items = make_frames(body, dress, generate("walk", 1.0, 0, body), [0, 12, 24], [-0.3, 0.5, 0.0])
    torch.manual_seed(0)
    model = FitGar(SIZES, TINY).eval()
    with torch.no_grad():
        set_stats(model, items)
    return model, items


def test_fitgar_stream_equals_the_eager_pass(fitgar_frames):
    """One frame and three frames of a garment: the stream's outputs (fixed tables, static pooling) are
    FitGar.forward's, with and without a round limit on the matching (the same matching: the pooling's scores
    are bit-identical, so no near tie can flip)."""
    model, items = fitgar_frames
    for n in (1, 3):
        batch = collate_frames(items[:n])
        with torch.no_grad():
            expected = model(batch)
            stream = FitGarStream(model, batch)
            got = stream(batch)
            limited = stream.step(*[batch[k] for k in FRAME_INPUTS], rounds=GRAPH_ROUNDS)
        assert bool(limited["exact"]) and "exact" not in got
        for k in ("coarse", "verts", "detail_displacement"):  # one thread: PyG's sums, to the bit
            assert torch.equal(got[k], expected[k]) and torch.equal(limited[k], got[k]), k
        assert stream.matches(batch) and not stream.matches(collate_frames(items[:1] if n == 3 else items[:2]))


# ---------------------------------------------------------------- what a CUDA graph needs, checked without a GPU

def test_captured_steps_have_no_data_dependent_host_work(data, fitgar_frames):  # noqa: F811
    """The steps CUDA graphs capture run on the meta device, which has no values: any ``.item()``, ``bool()``,
    ``nonzero``, boolean-mask indexing or shape taken from values would raise there (on a GPU they are the
    host synchronisations that break a capture). Shapes come out as the real frame's."""
    torch.manual_seed(0)
    bound = BoundSwinGar(SwinGar.from_data(data, MANY_HEADS).eval(), data.graphs[0])
    s = data.sequences[0].sequences[0]
    root, joints = torch.from_numpy(s.root[None, :2]), torch.from_numpy(s.joints[None, :2])
    with torch.no_grad():
        state = bound(root[:, :1], joints[:, :1])["state"]
        real = bound(root[:, 1:], joints[:, 1:], state)
        bound.to("meta")
        meta = bound.stream_step(root[:, 1:].to("meta"), joints[:, 1:].to("meta"),
                                 *(state[k].to("meta") for k in ("root", "joints", "gates")))
    assert {k: v.shape for k, v in meta.items()} == {k: real[k].shape for k in meta}

    model, items = fitgar_frames
    batch = collate_frames(items[:2])
    with torch.no_grad():
        real = model(batch)
        stream = FitGarStream(copy.deepcopy(model), batch, use_graphs=False)  # tables built from the garment
        stream.model.to("meta")
        for name in ("table", "valid", "edge_index", "faces", "index"):
            setattr(stream, name, getattr(stream, name).to("meta"))
        meta = stream.step(*[batch[k].to("meta") for k in FRAME_INPUTS], rounds=GRAPH_ROUNDS)
    assert meta["exact"].device.type == "meta"
    assert all(meta[k].shape == real[k].shape for k in real)
