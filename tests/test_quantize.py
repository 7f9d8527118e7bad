"""``loosefit quantize`` on the shipped garments (trained for real, 3,427 vertices): the quantized run animates as
its ``export-onnx --int8`` model steps (300 frames within 0.1 mm, where the original run is millimetres away), its
weights stay on their grid when quantized again, what was not rounded is untouched, and bad requests are refused
naming the folder or the weight."""

import numpy as np
import pytest
import torch
from torch import nn

from loosefit.animate import Animator, load_run
from loosefit.cli import main
from loosefit.errors import InputError
from loosefit.export_onnx import export_onnx, read_metadata
from loosefit.io.onnx_int8 import COLUMN_LEVELS
from loosefit.quantize import _matching_view, quantize_run
from tests.test_export_onnx import FRAMES, TOLERANCE, motion, stream  # noqa: F401 (the fixture)

SHIPPED = ["pretrained:skirt", "pretrained:skirt/jointnet"]


@pytest.fixture(scope="module")
def quantized(tmp_path_factory):
    root = tmp_path_factory.mktemp("quantized")
    for i, run in enumerate(SHIPPED):
        assert main(["quantize", run, "--out", str(root / str(i))]) == 0  # the command line's verb
    return {run: root / str(i) for i, run in enumerate(SHIPPED)}


@pytest.mark.parametrize("run", SHIPPED)
def test_a_quantized_run_animates_as_its_int8_model(run, quantized, motion, tmp_path):
    path = tmp_path / "int8.onnx"
    export_onnx(quantized[run], path, int8=True)
    weights = read_metadata(path)["weights"]
    assert weights["storage"] == "int8" and weights["run_on_int8_grid"] is True
    assert motion.num_frames == FRAMES
    steps = stream(path, motion)[0]
    animated = Animator(quantized[run]).animate(motion)
    gap = np.abs(steps - animated).max()
    original = np.abs(steps - Animator(run).animate(motion)).max()
    print(f"{run}: int8 model against the quantized run {gap * 1e3:.4f} mm, "
          f"against the original {original * 1e3:.3f} mm")
    assert gap <= TOLERANCE
    assert original > 2 * TOLERANCE  # the control: the rounding of the weights is what the run now holds


@pytest.mark.parametrize("run", SHIPPED)
def test_quantized_weights_stay_on_their_grid_and_nothing_else_moves(run, quantized, tmp_path):
    again = quantize_run(quantized[run], tmp_path / "again")
    _, before, _ = load_run(run)
    _, after, _ = load_run(quantized[run])
    biggest = max(float(p.detach().abs().max()) for n, p in after.named_parameters() if n in again["parameters"])
    assert again["largest_change"] <= 1e-6 * biggest  # rounding the rounded weights: a float unit at most
    assert again["matrices"] > 0
    rounded = set(again["parameters"])
    for (name, p), (_, q) in zip(before.named_parameters(), after.named_parameters()):
        if name in rounded:
            # within half a step of the coarsest scale (a many-row product's 7-bit columns)
            assert 0 < (p - q).abs().max() <= p.abs().max() / (2 * COLUMN_LEVELS) * 1.0001
        else:
            assert torch.equal(p, q), name
    for (name, b), (_, c) in zip(before.named_buffers(), after.named_buffers()):
        assert torch.equal(b, c), name


def test_a_weight_is_found_through_its_slice_and_written_back():
    layer = nn.Linear(7, 5)
    part = layer.weight.detach()[:, 2:6].T.numpy().copy()  # (4, 5), as the exporter writes a split first layer
    name, view = _matching_view(layer, part, "w")
    assert name == "weight" and tuple(view.shape) == (4, 5)
    with torch.no_grad():
        view.copy_(torch.zeros(4, 5))
    assert torch.all(layer.weight[:, 2:6] == 0) and torch.all(layer.weight[:, :2] != 0)
    with pytest.raises(InputError, match="no parameter of the model"):
        _matching_view(layer, part + 1.0, "folded")


def test_refusals_name_the_folder(quantized, tmp_path, capsys):
    assert main(["quantize", "pretrained:skirt", "--out", str(quantized["pretrained:skirt"])]) == 2
    assert "exists and is not empty" in capsys.readouterr().err
    with pytest.raises(InputError, match="no model.json|not a loosefit run"):
        quantize_run(tmp_path, tmp_path / "out")
