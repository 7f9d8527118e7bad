"""Each layer's ``reset_parameters`` is its one initialiser: building a layer draws exactly what a call of it
draws, and the same values as building its parts plainly (torch's and PyG's constructors) did."""

from __future__ import annotations

import pytest
import torch
from torch import nn
from torch_geometric.nn import GATConv

from loosefit.models.layers.decomposed_output import DecomposedOutput, DirectOutput
from loosefit.models.layers.edge_conv import EdgeConv
from loosefit.models.layers.edge_pool import EdgeContractionPooling
from loosefit.models.layers.gat_block import GATBlock
from loosefit.models.layers.gat_ln import GATLN
from loosefit.models.layers.gru import GRUHead
from loosefit.models.layers.init import undrawn
from loosefit.models.layers.lstm_gat_ln import LSTMGATLN
from loosefit.models.layers.mlp import MLP


def plain_parts(*parts) -> list[torch.Tensor]:
    """The parameters of modules built the plain way, in order, from seed 0."""
    torch.manual_seed(0)
    return [p.detach().clone() for make in parts for p in make().parameters()]


def state(module: nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.clone() for k, v in module.state_dict().items()}


LAYERS = {
    "mlp": (lambda: MLP([5, 7, 3]), [lambda: nn.Linear(5, 7), lambda: nn.Linear(7, 3)], None),
    "edge_conv": (lambda: EdgeConv(3, 8), [lambda: nn.Linear(6, 8)], None),
    "edge_pool": (lambda: EdgeContractionPooling(4), [lambda: nn.Linear(8, 1)], None),
    "gat_block": (lambda: GATBlock(5, 4, 3, 2), [lambda: nn.Linear(5, 4), lambda: GATConv(5, 3, heads=2)], None),
    "gru": (lambda: GRUHead(6, 5, 4, layers=2, out_scale=0.1),
            [lambda: nn.GRU(6, 5, num_layers=2, batch_first=True), lambda: nn.Linear(5, 4)], 0.1),
    "decomposed": (lambda: DecomposedOutput(5, 6, [8], magnitude_bias=0.7),
                   [lambda: nn.Linear(5, 8), lambda: nn.Linear(8, 1), lambda: nn.Linear(6, 8), lambda: nn.Linear(8, 3)],
                   None),
    "direct": (lambda: DirectOutput(5, [8], "plain"), [lambda: nn.Linear(5, 8), lambda: nn.Linear(8, 3)], None),
    "lstm_gat_ln": (lambda: LSTMGATLN(5, 6, 2), None, None),
    "gat_ln": (lambda: GATLN(5, 6, 2), None, None),
}


@pytest.mark.parametrize("name", sorted(LAYERS))
def test_construction_and_reset_draw_the_same_values(name):
    make, parts, out_scale = LAYERS[name]
    torch.manual_seed(0)
    layer = make()
    built, after_build = state(layer), torch.random.get_rng_state()
    with torch.no_grad():
        for p in layer.parameters():
            p.fill_(123.0)
    torch.manual_seed(0)
    layer.reset_parameters()
    assert torch.equal(torch.random.get_rng_state(), after_build)  # the same number of draws
    assert all(torch.equal(built[k], v) for k, v in layer.state_dict().items())
    if parts is None:
        return
    ref = plain_parts(*parts)
    assert torch.equal(torch.random.get_rng_state(), after_build)
    got = [p.detach() for p in layer.parameters()]
    assert len(got) == len(ref)
    if out_scale is not None:  # the read-out (last two parameters) starts scaled
        ref = ref[:-2] + [r * out_scale for r in ref[-2:]]
    if name == "decomposed":  # the magnitude's last bias starts at magnitude_bias
        ref[3] = torch.full_like(ref[3], 0.7)
    for g, r in zip(got, ref):
        assert torch.equal(g, r)


def test_undrawn_allocates_without_drawing():
    torch.manual_seed(0)
    before = torch.random.get_rng_state()
    linear = undrawn(nn.Linear, 4, 3)
    assert torch.equal(torch.random.get_rng_state(), before)
    assert linear.weight.device == torch.get_default_device() and linear.weight.shape == (3, 4)
    assert "channels=[5, 7, 3], final_activation=False" in repr(MLP([5, 7, 3]))
