"""On a GPU: CUDA graph replay of the streaming steps equals eager streaming (SwinGar's frame with its recurrent
state, FitGar's frame with its pooling), and the capture takes (a failed capture would fall back to eager
frames with a warning, which these tests refuse)."""

from __future__ import annotations

import copy

import pytest
import torch

from loosefit.models.fitgar_data import collate_frames
from loosefit.models.swingar import BoundSwinGar, SwinGar

from .test_streaming_step import MANY_HEADS, fitgar_frames  # noqa: F401  (fixture)
from .test_swingar import data, store  # noqa: F401  (fixtures)

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")


def test_swingar_cuda_graph_replay_equals_eager_streaming(data):  # noqa: F811
    torch.manual_seed(0)
    model = SwinGar.from_data(data, MANY_HEADS).eval()
    twin = copy.deepcopy(model)  # before .to(cuda) moves ``model`` with the first binding
    graphed = BoundSwinGar(model, data.graphs[0]).to("cuda")
    eager = BoundSwinGar(twin, data.graphs[0]).to("cuda")
    eager.use_graphs = False
    s = data.sequences[0].sequences[0]
    root, joints = torch.from_numpy(s.root[None, :8]).cuda(), torch.from_numpy(s.joints[None, :8]).cuda()
    with torch.no_grad():
        a = b = None
        for t in range(8):
            out_a = graphed(root[:, t:t + 1], joints[:, t:t + 1], a)
            out_b = eager(root[:, t:t + 1], joints[:, t:t + 1], b)
            a, b = out_a["state"], out_b["state"]
            torch.testing.assert_close(out_a["verts"], out_b["verts"], rtol=1e-4, atol=1e-5)
            torch.testing.assert_close(a["gates"], b["gates"], rtol=1e-4, atol=1e-5)
    captured = [g for g in graphed._graphs.values() if g is not None]
    assert len(captured) == 1, "the streaming step was not captured"


def test_fitgar_cuda_graph_replay_equals_eager(fitgar_frames):  # noqa: F811
    """Replay of the captured frame (as FitGar.forward streams on CUDA) equals the eager pass on the edge list."""
    model, items = fitgar_frames
    model = copy.deepcopy(model).to("cuda")
    eager = copy.deepcopy(model)
    eager.use_graphs = False
    with torch.no_grad():
        for n in (1, 2):
            batches = [{k: v.cuda() for k, v in collate_frames(items[t:t + n]).items()} for t in range(3 - n + 1)]
            for batch in batches:
                expected = eager(batch)
                got = model(batch)
                assert model._stream._graph is not None, "the FitGar frame was not captured"
                torch.testing.assert_close(got["verts"], expected["verts"], rtol=1e-4, atol=1e-5)
                torch.testing.assert_close(got["coarse"], expected["coarse"], rtol=1e-4, atol=1e-5)
