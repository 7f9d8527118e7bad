"""SwinGar end to end on a small simulated multi-garment store, on a CPU: simulate, train, animate, compare.

1. Simulate (Blender) the plan below: three training garments (two skirts and a dress, 426-879 vertices)
   and a held-out skirt (346 vertices) on the average Anny body, walk / spin / sway of 2 s; test split:
   the held-out skirt on every motion, and every garment on the held-out sway.
2. Train SwinGar with small CPU sizes (``SMALL`` below; 30 epochs vertex term only, then 15 with every
   term) twice: GAT-LN with ``alpha = 2`` and plain GAT (``alpha = null``), the ablation of SwinGar Fig. 9a.
3. Animate every sequence with each run from the garment's rest mesh (:class:`loosefit.animate.Animator`
   with ``garment=``) and report the RMSE against the simulation, next to body-LBS (the garment skinned
   with the skinning weights of its closest rest body vertex).

SwinGar's speed at the paper's sizes (streaming and batch 16) is measured by ``benchmarks/graph_speed.py``.

Each step is skipped when its output exists under ``--work`` (the store, a run's ``run.json``).

Run: .venv/bin/python benchmarks/swingar_small.py [--work /tmp/swingar-small]
(writes benchmarks/results/swingar-small.json)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

PLAN = """
name: swingar-e2e
garments:
  skirt-a: {template: skirt, seed: 0, edge_length: 0.05, params: {length: 0.45, flare: 25}}
  skirt-b: {template: skirt, seed: 2, edge_length: 0.045, params: {length: 0.5}}
  dress-a: {template: dress, seed: 1, edge_length: 0.06, params: {length: 0.5}}
  skirt-c: {template: skirt, seed: 5, edge_length: 0.05, params: {length: 0.5}}
motions:
  walk: {procedural: walk, seconds: 2.0, seed: 0}
  spin: {procedural: spin, seconds: 2.0, seed: 1}
  sway: {procedural: sway, seconds: 2.0, seed: 2}
sim_params:
  default: {preroll: 0.5}
split:
  test: {garments: [skirt-c], motions: [sway]}
"""

SMALL = {
    "model": {"graph_hidden": [16, 32], "graph_heads": [4, 4], "shape_mlp": [32, 16], "motion_hidden": 32,
              "motion_frames": 16, "body_mlp": [32, 16], "state_hidden": 32, "state_heads": 4,
              "blend_hidden": [32, 32], "blend_heads": 2, "corrective_hidden": 16, "corrective_heads": 2,
              "corrective_layers": [16, 3], "descriptor_samples": 64},
    "data": {"window": 15, "stride": 15},
    "train": {"batch_size": 4, "lr": 1.0e-3, "progress": False, "tensorboard": False, "device": "cpu",
              "stages": {"supervised": {"epochs": 30}, "all": {"epochs": 15}}},
}
VARIANTS = {"gat-ln-alpha-2": "2.0", "plain-gat": "null"}


def rmse_mm(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(((a - b) ** 2).sum(-1).mean()) * 1e3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", default="/tmp/swingar-small")
    args = parser.parse_args()
    from loosefit.animate import Animator
    from loosefit.body import AnnyBody
    from loosefit.cli import main as cli
    from loosefit.data.store import DatasetStore
    from loosefit.simulate import run_plan
    from loosefit.sim.attach import body_lbs

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    store_path = work / "data.zarr"
    if not store_path.exists():
        (work / "plan.yaml").write_text(PLAN)
        run_plan(work / "plan.yaml", store_path, progress=False)
    (work / "small.yaml").write_text(yaml.safe_dump(SMALL))
    history = {}
    for name, alpha in VARIANTS.items():
        run = work / f"run-{name}"
        if not (run / "run.json").exists():
            cli(["train", "--method", "swingar", "--data", str(store_path), "--out", str(run),
                 "--config", str(work / "small.yaml"), "--set", f"model.alpha={alpha}"])
        import csv

        with open(run / "metrics.csv", newline="") as f:
            history[name] = [{"stage": r["stage"], "epoch": int(r["epoch"]), "val_rmse_mm": float(r["val_rmse_mm"])}
                             for r in csv.DictReader(f)]
    torch.set_num_threads(1)
    store = DatasetStore.open(store_path)
    body = AnnyBody()
    animators: dict = {name: {} for name in VARIANTS}
    rows = []
    for seq_name in sorted(store.sequence_names()):
        seq = store.sequence(seq_name)
        garment, motion, truth = store.garment(seq.garment), store.motion(seq.motion), seq.verts[:]
        row = {"sequence": seq_name, "split": seq.split, "garment_vertices": garment.num_verts,
               "body-lbs": rmse_mm(body_lbs(garment.verts, body, motion), truth)}
        for name in VARIANTS:
            if seq.garment not in animators[name]:
                animators[name][seq.garment] = Animator(work / f"run-{name}", garment=garment, body=body)
            row[name] = rmse_mm(animators[name][seq.garment].animate(motion), truth)
        rows.append(row)
    unseen = [r for r in rows if r["sequence"].startswith("skirt-c")]
    summary = {k: float(np.mean([r[k] for r in unseen])) for k in ["body-lbs", *VARIANTS]}
    results = {"plan": yaml.safe_load(PLAN), "config": SMALL, "rmse_mm": rows,
               "unseen_garment_mean_rmse_mm": summary, "validation_history": history}
    save_results("swingar-small", results)


if __name__ == "__main__":
    main()
