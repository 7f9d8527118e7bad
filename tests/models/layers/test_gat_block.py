"""GAT block with the self-reinforced stream (FitGar Sec. 4.3) against hand computations."""

import pytest
import torch

from loosefit.errors import InputError
from loosefit.models.layers.gat_block import GATBlock


def _block(seed=0, **kw):
    torch.manual_seed(seed)
    block = GATBlock(5, 3, 2, heads=4, **kw)
    with torch.no_grad():  # GATConv starts with a zero bias: make it count in the checks
        block.attention.bias.normal_()
    return block


def test_output_size_is_self_plus_heads_times_channels():
    block = _block()
    x = torch.randn(7, 5)
    edges = torch.tensor([[0, 1, 2, 3], [1, 2, 3, 4]])
    assert block.out_channels == 3 + 4 * 2
    assert block(x, edges).shape == (7, 11)
    assert GATBlock.of_width(7, 256).out_channels == 256
    wide = GATBlock.of_width(7, 256)
    assert wide.self_stream.out_features == 128 and wide.attention.out_channels == 32 and wide.attention.heads == 4


def test_attention_one_hot_on_the_self_loop_is_two_linear_maps():
    """Without edges every node attends only to its own self loop (softmax over one entry is 1):
    the block is [W_s x + b_s, W x + b]."""
    block = _block()
    x = torch.randn(6, 5)
    out = block(x, torch.zeros(2, 0, dtype=torch.long))
    expected_self = x @ block.self_stream.weight.T + block.self_stream.bias
    expected_agg = x @ block.attention.lin.weight.T + block.attention.bias
    torch.testing.assert_close(out, torch.cat([expected_self, expected_agg], 1), rtol=1e-5, atol=1e-6)


def test_uniform_attention_averages_the_neighbourhood():
    """With zero attention vectors every neighbour (self loop included) weighs the same: the
    aggregation stream is the mean of W x_j over j in N(i) + i, computed here by hand."""
    block = _block(1)
    with torch.no_grad():
        block.attention.att_src.zero_()
        block.attention.att_dst.zero_()
    x = torch.randn(4, 5)
    # a path 0 - 1 - 2, node 3 alone; both directions
    edges = torch.tensor([[0, 1, 1, 2], [1, 0, 2, 1]])
    out = block(x, edges)
    wx = x @ block.attention.lin.weight.T
    mean = torch.stack([(wx[0] + wx[1]) / 2, (wx[0] + wx[1] + wx[2]) / 3, (wx[1] + wx[2]) / 2, wx[3]])
    torch.testing.assert_close(out[:, 3:], mean + block.attention.bias, rtol=1e-5, atol=1e-6)
    # the self stream ignores the neighbours
    torch.testing.assert_close(out[:, :3], x @ block.self_stream.weight.T + block.self_stream.bias)


def test_neighbours_change_the_aggregation_but_not_the_self_stream():
    block = _block(2)
    x = torch.randn(3, 5)
    edges = torch.tensor([[0, 1], [1, 0]])
    before = block(x, edges)
    x2 = x.clone()
    x2[0] += 1.0  # node 1 sees node 0
    after = block(x2, edges)
    assert torch.equal(before[1, :3], after[1, :3])
    assert (before[1, 3:] - after[1, 3:]).abs().max() > 1e-3
    assert torch.equal(before[2], after[2])  # node 2 is not connected


def test_bad_sizes():
    with pytest.raises(InputError):
        GATBlock(3, 0, 2)
    with pytest.raises(InputError):
        GATBlock.of_width(3, 10, heads=4)  # 5 aggregation features do not split into 4 heads
