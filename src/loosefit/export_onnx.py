"""``loosefit export-onnx``: a trained garment as one ONNX model that animates one frame per call.

The model is :class:`loosefit.models.step_graph.StepGraph` traced by torch's ONNX exporter: the motion
features, the network and the return to the world all happen inside it, so a game engine or a web page
(onnxruntime, onnxruntime-web) needs nothing from loosefit. The contract (``docs/onnx.md``)::

    inputs   joint_rotations (J, 3) float32  axis-angle, radians, local rotations of the run's rig
             root_position   (3,)   float32  metres, Z up (the Motion's translation)
             state           (S,)   float32  initial_state from the metadata, then the last next_state
    outputs  vertices        (V, 3) float32  metres, Z up, world
             next_state      (S,)   float32
             bone_transforms (B, 4, 4) float32  (with bones=True) world matrices of the bones' nodes

One ``metadata_props`` entry, key :data:`METADATA_KEY`, holds a JSON object: format version, method, fps,
joint names in input order, vertex count, faces, the initial state and the state's layout (name, offset, shape,
unit, axes per field), units and up axis (:func:`read_metadata`).
"""

from __future__ import annotations

import argparse
import json
import logging
import warnings
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.paths import atomic_path

log = logging.getLogger(__name__)

#: The ``metadata_props`` key of the model's description.
METADATA_KEY = "loosefit"
#: Version of the contract; a reader refuses another.
FORMAT_VERSION = 1
#: ONNX operator set of the exported graph.
OPSET = 17
INPUTS = ("joint_rotations", "root_position", "state")
OUTPUTS = ("vertices", "next_state")
BONE_OUTPUT = "bone_transforms"
#: Methods that animate through other inputs than one body pose per frame (a garment graph, a static pair).
NOT_EXPORTED = {
    "swingar": "SwinGar animates any garment through a garment graph built at run time; export-onnx does not "
               "cover it yet (use loosefit animate)",
    "fitgar": "FitGar is a static (garment, pose) model; export-onnx does not cover it yet (use loosefit animate)",
    "collision": "a collision run is a body distance field, not a garment model",
}


def export_onnx(run_dir: str | Path, out: str | Path, checkpoint: str = "best", bones: bool = False,
                int8: bool = False) -> dict:
    """Write the run's garment model as one ONNX step model (module doc) to ``out``.

    Args:
        run_dir: a run folder of body-lbs, virtualbones or jointnet (or a shipped garment, ``pretrained:...``).
        out: the ``.onnx`` file written.
        checkpoint: ``"best"``, ``"last"`` or a checkpoint path (:func:`loosefit.animate.load_run`).
        bones: also output the bones' world transforms (``bone_transforms``).
        int8: store the large weight matrices as int8 (:mod:`loosefit.io.onnx_int8`): about 30 % of the file and
            about twice the frames per second on one CPU thread; needs onnxruntime's ``MatMulNBits`` and
            ``DynamicQuantizeMatMul``. The products are those of the rounded weights (within about 0.02 mm of the
            vertices), so a run made by :func:`loosefit.quantize.quantize_run` animates as its int8 model does;
            any other run differs from its int8 model by what rounding its weights does (up to about 1 mm measured,
            ``benchmarks/README.md``).

    Returns:
        ``{"path", "bytes", "method", "vertices", "joints", "state_size", "bones", "weights"}`` (``weights``:
        ``"float32"``, or ``"int8"`` with the counts of :func:`~loosefit.io.onnx_int8.quantize_model` and
        ``run_on_int8_grid``: whether the run's own weights are those rounded values).

    Raises:
        InputError: not a run folder, a missing or corrupt ``model.json`` or checkpoint (naming the file), or a
            method without a one-frame graph.
    """
    from loosefit.animate import load_run
    from loosefit.extras import require

    onnx = require("onnx", "loosefit export-onnx")
    out = Path(out)
    if out.suffix.lower() != ".onnx":
        raise InputError("the exported model is an .onnx file", out)
    check_step_method(run_dir)
    meta, model, _ = load_run(run_dir, checkpoint)
    with atomic_path(out) as tmp:  # a failed export leaves an earlier file as it was
        proto, graph = trace_step_model(model, tmp, bones)
        weights: dict = {"storage": "float32"}
        if int8:
            from loosefit.io.onnx_int8 import BLOCK_SIZE, quantize_model

            proto, counts = quantize_model(proto)
            weights = {"storage": "int8", "block_size": BLOCK_SIZE, **counts,
                       "run_on_int8_grid": bool(meta.get("weights", {}).get("int8_grid"))}
        entry = proto.metadata_props.add()
        entry.key, entry.value = METADATA_KEY, json.dumps({**describe(graph, meta, model), "weights": weights})
        proto.producer_name = "loosefit"
        onnx.checker.check_model(proto)
        onnx.save(proto, str(tmp))
    J, V = graph.num_joints, int(model.template.shape[0])
    return {"path": str(out), "bytes": out.stat().st_size, "method": graph.method, "vertices": V, "joints": J,
            "state_size": graph.state_size, "bones": int(graph.bone_rest_positions().shape[0]) if bones else 0,
            "weights": weights}


def check_step_method(run_dir: str | Path) -> None:
    """Refuse a run whose method has no one-frame graph (:data:`NOT_EXPORTED`, or none in ``STEP_METHODS``),
    naming the run folder."""
    from loosefit.animate import read_run_meta
    from loosefit.models.step_graph import STEP_METHODS

    method = read_run_meta(run_dir)["method"]
    if method in NOT_EXPORTED:
        raise InputError(NOT_EXPORTED[method], run_dir)
    if method not in STEP_METHODS:
        raise InputError(f"{method} has no one-frame graph; export-onnx covers {', '.join(STEP_METHODS)}", run_dir)


def trace_step_model(model, path: Path, bones: bool = False):
    """``model``'s one-frame graph (:class:`~loosefit.models.step_graph.StepGraph`) traced to ONNX at ``path``:
    ``(onnx.ModelProto as written, the StepGraph)``, float32 weights, no metadata yet."""
    import onnx
    import torch

    from loosefit.models.step_graph import StepGraph

    graph = StepGraph(model.float().eval(), bones=bones)
    example = (torch.zeros(graph.num_joints, 3), torch.tensor([0.0, 0.0, 1.0]),
               torch.from_numpy(graph.initial_state()))
    outputs = list(OUTPUTS) + ([BONE_OUTPUT] if bones else [])
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the legacy exporter's deprecation notice and tracer notes
        torch.onnx.export(graph, example, str(path), input_names=list(INPUTS), output_names=outputs,
                          opset_version=OPSET, dynamo=False, do_constant_folding=True)
    return onnx.load(str(path)), graph


def describe(graph, meta: dict, model) -> dict:
    """The model's metadata (module doc) as a JSON-able dict."""
    from loosefit.motion.motion import DEFAULT_FPS

    d = {"format": "loosefit-onnx-step", "format_version": FORMAT_VERSION, "method": graph.method,
         "garment": meta.get("garment"), "fps": DEFAULT_FPS, "joint_names": joint_names(meta, graph.num_joints),
         "num_joints": graph.num_joints, "vertex_count": int(model.template.shape[0]),
         "faces": model.faces.cpu().numpy().astype(np.int64).reshape(-1).tolist(),
         "state_size": graph.state_size, "initial_state": graph.initial_state().tolist(),
         "state_layout": [f.to_json() for f in graph.layout()],
         "units": {"length": "m", "angle": "rad", "time": "frame"}, "up_axis": "Z", "forward_axis": "-Y",
         "handedness": "right",
         "inputs": {"joint_rotations": [graph.num_joints, 3], "root_position": [3], "state": [graph.state_size]},
         "outputs": {"vertices": [int(model.template.shape[0]), 3], "next_state": [graph.state_size]}}
    if graph.bones:
        rest = graph.bone_rest_positions().detach().cpu().numpy()
        d["outputs"][BONE_OUTPUT] = [len(rest), 4, 4]
        d["bones"] = {"count": len(rest), "rest_positions": rest.astype(np.float64).round(7).reshape(-1).tolist(),
                      "kind": "body joints" if graph.method == "body-lbs" else "virtual bones"}
    return d


def joint_names(meta: dict, count: int) -> list[str]:
    """The names of the run's ``count`` joints in input order: the model's own (JointNet), else those of a
    training motion in the run's store, else the default Anny rig's when it has as many joints."""
    names = meta["sizes"].get("joint_names")
    if names and len(names) == count:
        return list(names)
    try:
        from loosefit.data import DatasetStore

        store = DatasetStore.open(meta["data"], mode="r")
        motion = store.motion(store.sequence(meta["train_sequences"][0]).motion)
        if len(motion.joint_names) == count:
            return list(motion.joint_names)
    except Exception as e:  # the store may have moved: the rig's names below
        log.info("joint names not read from the run's store (%s: %s)", type(e).__name__, e)
    from loosefit.body import AnnyBody

    names = list(AnnyBody().joint_names)
    if len(names) != count:
        raise InputError(f"the run's {count} joints have no names (its store is gone and the default rig has "
                         f"{len(names)} joints)")
    return names


def read_metadata(path: str | Path) -> dict:
    """The :data:`METADATA_KEY` metadata of an exported model (module doc).

    Raises:
        InputError: not an ONNX model, no loosefit metadata, or another format version; the message names the file.
    """
    from loosefit.extras import require

    onnx = require("onnx", "reading an exported model")
    path = Path(path)
    try:
        proto = onnx.load(str(path), load_external_data=False)
    except Exception as e:  # protobuf raises its own decode errors
        raise InputError(f"not an ONNX model ({type(e).__name__}: {e})", path) from None
    entries = {p.key: p.value for p in proto.metadata_props}
    if METADATA_KEY not in entries:
        raise InputError(f"no {METADATA_KEY!r} metadata: not written by loosefit export-onnx", path)
    try:
        meta = json.loads(entries[METADATA_KEY])
    except ValueError as e:
        raise InputError(f"the {METADATA_KEY!r} metadata is not JSON ({e})", path) from None
    if not isinstance(meta, dict) or meta.get("format_version") != FORMAT_VERSION:
        raise InputError(f"metadata format version {meta.get('format_version') if isinstance(meta, dict) else None!r}; "
                         f"this loosefit reads {FORMAT_VERSION}", path)
    return meta


def add_arguments(sp: argparse.ArgumentParser) -> None:
    """The ``export-onnx`` verb's arguments (``loosefit.cli_commands.cmd_export_onnx`` calls :func:`export_onnx`)."""
    sp.add_argument("run", help="run folder written by loosefit train (body-lbs, virtualbones or jointnet)")
    sp.add_argument("--out", required=True, help="garment.onnx")
    sp.add_argument("--checkpoint", default="best", help="best (by validation; last when the run validated on "
                    "nothing), last or a checkpoint path")
    sp.add_argument("--bones", action="store_true", help="also output the bones' world transforms (GPU skinning)")
    sp.add_argument("--int8", action="store_true", help="large weight matrices in int8: about 30 %% of the file, "
                    "about 2x faster on a CPU (not for the live page); a run made by loosefit quantize animates as "
                    "this model does, any other within about 1 mm")
