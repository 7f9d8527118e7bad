"""The gradient of each FitGar loss term alone (coarse: FitGar Sec. 4.3, detail: Sec. 4.4) on one skirt frame
in float64: it matches central finite differences on a few entries of every parameter of its stage, and the
detail term never reaches the coarse generator (frozen in that stage) while it does reach the attribute parser
through FitGar Eq. 7's product."""

from __future__ import annotations

import pytest
import torch

from loosefit.models.fitgar import FitGar
from loosefit.models.fitgar_data import collate_frames

from .conftest import central_difference
from .fitgar_fixtures import TINY, make_frames, set_stats
from .test_fitgar import SIZES


@pytest.fixture(scope="module")
def frame(body):
    from loosefit.garment import make_garment
    from loosefit.motion.procedural import generate

    skirt = make_garment("skirt", body, seed=0, edge_length=0.06)
    _, items = make_frames(body, skirt, generate("walk", 0.5, 0, body), [7], [0.2, -0.1, 0.4])
    return items


def model_and_batch(items) -> tuple[FitGar, dict]:
    torch.manual_seed(0)
    model = FitGar(SIZES, TINY)
    with torch.no_grad():
        set_stats(model, items)
    model = model.double()
    model.use_graphs = False
    batch = {k: v.double() if v.is_floating_point() else v for k, v in collate_frames(items).items()}
    return model, batch


@pytest.mark.parametrize("stage", ["coarse", "detail"])
def test_stage_term_gradient_matches_central_differences(frame, stage):
    model, batch = model_and_batch(frame)
    model.zero_grad(set_to_none=True)
    model.loss_terms(batch, stage)[stage].backward()
    own = {id(p) for p in model.stage_parameters(stage)}
    checked = 0
    for name, p in model.named_parameters():
        if id(p) not in own:
            assert p.grad is None or p.grad.abs().max() == 0, f"the {stage} term reaches {name}"
            continue
        assert p.grad is not None, name
        k = int(p.grad.view(-1).abs().argmax())  # the entry the term depends on most
        numeric = central_difference(lambda: float(model.loss_terms(batch, stage)[stage]), p, k)
        assert float(p.grad.view(-1)[k]) == pytest.approx(numeric, rel=1e-4, abs=1e-9), name
        checked += 1
    assert checked == len(own)


def test_detail_term_reaches_the_parser_and_not_the_coarse_generator(frame):
    model, batch = model_and_batch(frame)
    model.zero_grad(set_to_none=True)
    model.loss_terms(batch, "detail")["detail"].backward()
    parser = list(model.parser.parameters())
    assert parser and all(p.grad is not None and p.grad.abs().sum() > 0 for p in parser)
    coarse = [*model.coarse_first.parameters(), *model.coarse.parameters()]
    assert all(p.grad is None for p in coarse)
