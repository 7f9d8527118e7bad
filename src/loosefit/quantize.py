"""``loosefit quantize``: a copy of a run whose weights lie on the int8 grid that ``export-onnx --int8`` stores.

``export-onnx --int8`` (:mod:`loosefit.io.onnx_int8`) rounds each large weight matrix of the one-frame graph to
int8 blocks and multiplies the rounded values exactly enough that the exported model's vertices stay within about
0.02 mm of the same graph with those rounded weights in float32. What separates it from ``loosefit animate`` on the
original run is the rounding of the weights itself (up to about 1 mm of the vertices measured,
``benchmarks/README.md``).
This module puts the rounded values back into the run's parameters: the quantized run animates, evaluates and
renders as its int8 model does in a game engine, and its own accuracy can be measured as any run's.

How a weight of the ONNX graph is found among the model's parameters: the exporter writes each as the parameter
itself, reshaped, transposed, or a slice of it (JointNet's first bone layer is split in two by the one-frame graph);
each rewritten initializer is matched by value against those views of every parameter, and the rounded values are
written through the view that matched. A weight no parameter yields (a product the exporter folded) is refused by
name, and the result is checked: the quantized run exported again rounds to the values it holds.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.paths import atomic_folder

#: How far (relative to a matrix's largest weight) the quantized run's weights may sit from its own rounding:
#: recomputing a block's scale from its rounded values moves it by a float32 unit at most.
GRID_TOLERANCE = 1e-6


def quantize_run(run_dir: str | Path, out: str | Path, checkpoint: str = "best") -> dict:
    """Write a copy of the run at ``run_dir`` to the folder ``out`` with its weights rounded as ``export-onnx
    --int8`` rounds them (module doc).

    The copy holds ``model.json`` (with ``"weights": {"int8_grid": true, "quantized_from", "checkpoint"}``), the
    method's config and one complete checkpoint of the rounded weights; it animates, evaluates and exports as any
    run (its training state is not kept: it is a finished model).

    Returns:
        ``{"path", "method", "matrices", "parameters", "weights_rounded", "largest_change"}``: the matrices of the
        graph rounded, the parameters they came from, how many weights that is, and the largest change of a weight.

    Raises:
        InputError: ``out`` exists and is not empty, not a run folder of a method ``export-onnx`` covers, a
            corrupt run (naming the file), or a graph weight that is no view of a parameter.
    """
    import torch

    from loosefit.animate import load_run
    from loosefit.config import save_config
    from loosefit.export_onnx import check_step_method, trace_step_model
    from loosefit.io.onnx_int8 import quantize_model
    from loosefit.train.run import RunDir
    from loosefit.training import METHOD_CONFIG, MODEL_META, _save_weights

    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise InputError("the quantized run's folder exists and is not empty: name a new one", out)
    check_step_method(run_dir)
    meta, model, cfg = load_run(run_dir, checkpoint)
    model = model.float().eval()
    with tempfile.TemporaryDirectory() as tmp:
        proto, _ = trace_step_model(model, Path(tmp) / "float.onnx")
        rounded: dict = {}
        quantize_model(proto, rounded=rounded)
        weights = _initializers(proto, rounded)
        changed: set[str] = set()
        largest = 0.0
        with torch.no_grad():
            for name, values in rounded.items():
                param, view = _matching_view(model, weights[name], name)
                largest = max(largest, float(np.abs(values - weights[name]).max()))
                view.copy_(torch.from_numpy(np.ascontiguousarray(values)))
                changed.add(param)
        again: dict = {}
        quantize_model(trace_step_model(model, Path(tmp) / "again.onnx")[0], rounded=again)
    for name, values in rounded.items():  # the rounding of the rounded run is itself
        scale = max(float(np.abs(values).max()), 1e-30)
        if name not in again or np.abs(again[name] - values).max() > GRID_TOLERANCE * scale:
            raise InputError(f"the graph's weight {name} does not stay on its int8 grid once written back (a "
                             f"parameter used by two products rounded differently)", run_dir)

    with atomic_folder(out) as partial:  # renamed when whole: never half a run
        run = RunDir(partial)
        meta = {**meta, "weights": {"int8_grid": True, "quantized_from": str(run_dir), "checkpoint": checkpoint}}
        (run.path / MODEL_META).write_text(json.dumps(meta, indent=1))
        save_config(run.path / METHOD_CONFIG, cfg)
        _save_weights(model, run, ["fixed"])
    return {"path": str(out), "method": meta["method"], "matrices": len(rounded), "parameters": sorted(changed),
            "weights_rounded": int(sum(v.size for v in rounded.values())), "largest_change": largest}


def _initializers(proto, names) -> dict[str, np.ndarray]:
    from onnx import numpy_helper

    return {t.name: numpy_helper.to_array(t) for t in proto.graph.initializer if t.name in names}


def _matching_view(model, weight: np.ndarray, name: str):
    """``(parameter name, torch view of it)`` whose values are ``weight``'s exactly, in ``weight``'s shape."""
    for pname, param in model.named_parameters():
        if param.numel() < weight.size:
            continue
        for view in _candidate_views(param, weight):
            if view.shape == weight.shape and np.array_equal(view.detach().numpy(), weight):
                return pname, view
            if view.numel() == weight.size and view.is_contiguous():
                flat = view.view(weight.shape)
                if np.array_equal(flat.detach().numpy(), weight):
                    return pname, flat
    raise InputError(f"the graph's weight {name} {tuple(weight.shape)} is no parameter of the model, nor a "
                     f"transpose or slice of one: it cannot be rounded in the run")


def _candidate_views(param, weight: np.ndarray):
    """Views of ``param``'s data (sharing its storage) of ``weight``'s size that the exporter writes as a weight:
    the parameter reshaped or with its last two axes swapped, and for a matrix its row and column slices either way
    up (only those whose first value matches)."""
    data = param.data
    if data.numel() == weight.size:
        yield data
        if data.dim() >= 2:
            yield data.transpose(-1, -2)
        return
    if data.dim() != 2 or weight.ndim != 2:
        return
    first = weight.reshape(-1)[0]
    for axis in (0, 1):
        for transposed in (False, True):
            length = weight.shape[1 - axis] if transposed else weight.shape[axis]
            other = weight.shape[axis] if transposed else weight.shape[1 - axis]
            if other != data.shape[1 - axis] or length >= data.shape[axis]:
                continue
            for start in range(data.shape[axis] - length + 1):
                part = data.narrow(axis, start, length)
                view = part.T if transposed else part
                if view[0, 0].item() == first:
                    yield view


def add_arguments(sp) -> None:
    """The ``quantize`` verb's arguments (``loosefit.cli_commands.cmd_quantize`` calls :func:`quantize_run`)."""
    sp.add_argument("run", help="run folder (body-lbs, virtualbones or jointnet), or pretrained:...")
    sp.add_argument("--out", required=True, help="the quantized run's folder (a new one)")
    sp.add_argument("--checkpoint", default="best", help="best (by validation; last when the run validated on "
                    "nothing), last or a checkpoint path")
