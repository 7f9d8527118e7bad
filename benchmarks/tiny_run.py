"""A tiny end-to-end run whose numbers a refactoring must not change.

Simulates a two-motion plan with Blender, prepares it (6 bones), trains tiny VirtualBones and JointNet
networks for a few epochs and prints, as one JSON line: the plan's job hashes, the rig's errors, every
epoch's training terms and validation metrics, and the parameter counts (wall-clock seconds left out).
Run it on two source trees and compare the lines (about 2 minutes each on 2 cores)::

    PYTHONPATH=OLD/src python benchmarks/tiny_run.py | tail -1 > old.json
    PYTHONPATH=NEW/src python benchmarks/tiny_run.py | tail -1 > new.json
    cmp old.json new.json
"""

import json
import tempfile
from pathlib import Path

import torch

from loosefit.rig.prepare import prepare
from loosefit.sim import load_plan
from loosefit.simulate import run_plan

try:
    from loosefit.training import train_model
except ImportError:  # a tree from before loosefit.training existed
    from loosefit.train.pipeline import train_model

PLAN = """
name: tiny
garments:
  skirt: {template: skirt, seed: 0, edge_length: 0.05, params: {length: 0.45, flare: 25}}
motions:
  walk: {procedural: walk, seconds: 1.0, seed: 0}
  sway: {procedural: sway, seconds: 1.0, seed: 2}
sim_params:
  default: {preroll: 0.5, bending: 1e-5}
split:
  test: {motions: [sway]}
"""
#: Tiny networks and a few epochs: the point is the exact numbers, not their quality.
OVERRIDES = {
    "virtualbones": ["model.lf_hidden=16", "model.hf_hidden=16", "model.edge_channels=[8]",
                     "train.stages.low.epochs=2", "train.stages.high.epochs=2"],
    "jointnet": ["model.gru_hidden=16", "model.features=16", "model.bone_mlp=[16]", "model.psd_mlp=[16]",
                 "model.psd_shapes=4", "train.stages.stage1.epochs=2", "train.stages.stage2.epochs=1"],
}
COMMON = ["train.progress=false", "train.tensorboard=false", "data.window=20", "data.stride=20", "data.burn_in=4"]


def main() -> None:
    torch.set_num_threads(1)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "p.yaml").write_text(PLAN)
        out["jobs"] = {j.id: j.hash for j in load_plan(tmp / "p.yaml").jobs}
        run_plan(tmp / "p.yaml", tmp / "d.zarr", progress=False)
        summary = prepare(tmp / "d.zarr", bones=6, progress=False)["garments"]
        out["prepare"] = {g: {k: v for k, v in e.items() if "seconds" not in k} for g, e in summary.items()}
        for method, overrides in OVERRIDES.items():
            r = train_model(method, tmp / "d.zarr", "skirt+average", tmp / method, overrides=overrides + COMMON)
            out[method] = {"val": r.val_metrics, "train": r.train_metrics, "params": r.parameter_count,
                           "step": r.global_step,
                           "history": [{k: v for k, v in h.items() if "seconds" not in k} for h in r.history]}
    print(json.dumps(out, sort_keys=True, default=str))


if __name__ == "__main__":
    main()
