"""Defaults of the model contract: stages, stage parameters, collate, batch sizes, device moves."""

from __future__ import annotations

from collections import namedtuple

import pytest
import torch
from torch import nn
from torch.utils.data import default_collate

from loosefit.train.protocol import (
    TrainableModel,
    batch_size,
    collate_fn,
    model_stages,
    parameter_count,
    stage_parameters,
    to_device,
)
from tests.train.conftest import SineGRU


class Plain(nn.Module):
    def __init__(self):
        super().__init__()
        self.a = nn.Linear(2, 3)
        self.b = self.a  # shared module: its parameters count once
        self.frozen = nn.Parameter(torch.zeros(4), requires_grad=False)

    def training_loss(self, batch, stage):
        return self.a(batch).sum(), {}

    def validation_metrics(self, batch, stage):
        return {}


def test_defaults_for_a_plain_model():
    model = Plain()
    assert isinstance(model, TrainableModel)
    assert model_stages(model) == ["all"]
    assert [p.shape for p in stage_parameters(model, "all")] == [(3, 2), (3,)]  # frozen one left out
    assert collate_fn(model) is default_collate
    assert parameter_count(model) == 6 + 3 + 4


def test_model_hooks_are_used():
    model = SineGRU(hidden=4)
    assert model_stages(model) == ["encoder", "head"]
    assert {id(p) for p in stage_parameters(model, "head")} == {id(model.head.weight), id(model.head.bias)}


def test_batch_size_inference():
    model = Plain()
    assert batch_size(model, torch.zeros(5, 2)) == 5
    assert batch_size(model, {"name": ["a", "b"], "x": torch.zeros(3, 7)}) == 3
    assert batch_size(model, [torch.zeros(4, 1), torch.zeros(4)]) == 4
    assert batch_size(model, [{"x": 1}, {"x": 2}]) == 2
    with pytest.raises(TypeError, match="define model.batch_size"):
        batch_size(model, 3.0)


def test_to_device_walks_containers():
    Pair = namedtuple("Pair", "u v")
    batch = {"x": torch.zeros(2), "seq": [torch.ones(1), (torch.ones(2), "s")], "pair": Pair(torch.ones(3), 4)}
    moved = to_device(batch, torch.device("meta"))
    assert moved["x"].device.type == "meta" and moved["seq"][0].device.type == "meta"
    assert moved["seq"][1][0].device.type == "meta" and moved["seq"][1][1] == "s"
    assert isinstance(moved["pair"], Pair) and moved["pair"].u.device.type == "meta" and moved["pair"].v == 4
