"""JointNet at the paper's widths on a small store: does a short training lower the loss, and what does
the held-out error do? One row per variant (optimiser and learning rate, initialisation of the bone
MLP's last layer, gradient clipping, the Fourier features' scale and how they join the bone features),
each from the same seed, the same windows in the same order, against VirtualBones on the same store.

Each variant trains JointNet's first stage (no PSD, paper Sec. 4.2) for ``--steps`` optimiser steps with
batches of ``--batch`` windows and records every step's loss, the largest bone-MLP output and the
gradient norm, and every ``--eval-every`` steps the RMSE of the skinned garment on the store's test
sequences (whole sequences from a zero state). VirtualBones' low-frequency module trains the same way
(its own config: Adam, lr 1e-3, gradient norm clipped at 1).

Variants (``--variants``, comma-separated; parts joined with ``+`` apply in order, e.g.
``rmsprop-torch+init-torch+add``, the model and optimiser as they were before they were fixed):

- ``paper``: the config file as it is (``configs/models/jointnet.yaml``).
- ``rmsprop``: RMSProp with its squared-gradient average corrected for its zero start;
  ``rmsprop-torch``: torch's RMSprop, uncorrected; ``adam``: Adam (betas 0.9, 0.999).
- ``lr1e-4``: learning rate 1e-4; ``clip``: the gradient norm clipped at 1.
- ``init-zero`` / ``init-torch``: the bone MLP's last layer starts at zero / drawn as any linear layer.
- ``concat`` / ``add``: the Fourier features concatenated with (Fig. 2) / added to (Eq. 4) the bone
  features; ``no-fourier``: their coefficients held at zero; ``scale0.5``: frequencies of 0.5 cycles/m.

Run: .venv/bin/python benchmarks/experiments/jointnet_stability.py --data STORE.zarr --garment skirt+average
         [--steps 60] [--variants paper,rmsprop-torch+init-torch+add,...] [--virtualbones] [--name NAME]
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import machine, save_results  # noqa: E402

from loosefit.config import load_config  # noqa: E402
from loosefit.models.dataset import GarmentSequences, WindowDataset  # noqa: E402
from loosefit.models.jointnet import Config as JointNetRunConfig, JointNet  # noqa: E402
from loosefit.models.virtualbones import Config as VirtualBonesRunConfig, VirtualBones  # noqa: E402
from loosefit.train.losses import masked_errors_mm  # noqa: E402
from loosefit.train.protocol import collate_fn  # noqa: E402
from loosefit.train.seeding import seed_everything  # noqa: E402
from loosefit.train.trainer import _optimizer  # noqa: E402

CONFIGS = Path(__file__).resolve().parents[2] / "configs" / "models"

#: Config overrides of each variant part (applied after the config file and the run's window settings).
OVERRIDES = {
    "paper": [],
    "rmsprop": ["train.optimizer=rmsprop"],
    "rmsprop-torch": ["train.optimizer=rmsprop-torch"],
    "adam": ["train.optimizer=adam"],
    "lr1e-4": ["train.lr=1.0e-4"],
    "clip": ["train.grad_clip=1.0"],
    "init-zero": ["model.bone_init=zero"],
    "init-torch": ["model.bone_init=torch"],
    "concat": ["model.fourier=concat"],
    "add": ["model.fourier=add"],
    "no-fourier": [],
    "scale0.5": ["model.fourier_scale=0.5"],
}


def variant_overrides(name: str) -> list[str]:
    parts = name.split("+")
    unknown = [p for p in parts if p not in OVERRIDES]
    if unknown:
        raise SystemExit(f"unknown variants {unknown}; known: {sorted(OVERRIDES)}")
    return [o for p in parts for o in OVERRIDES[p]]


def batches(dataset, batch: int, steps: int, collate, seed: int):
    """``steps`` batches: shuffled passes over the windows, the same for every variant."""
    g = torch.Generator().manual_seed(seed)
    order: list[int] = []
    for _ in range(steps):
        if len(order) < batch:
            order += torch.randperm(len(dataset), generator=g).tolist()
        yield collate([dataset[i] for i in order[:batch]])
        order = order[batch:]


def held_out_rmse(model, test: GarmentSequences, kind: str) -> float:
    """RMSE (mm) of the first stage's garment over whole test sequences from a zero state."""
    sq, n = 0.0, 0
    model.eval()
    with torch.no_grad():
        for s in test.sequences:
            root, joints = torch.from_numpy(s.root)[None], torch.from_numpy(s.joints)[None]
            out = model(root, joints, psd=False) if kind == "jointnet" else model(root, joints)
            pred = out["verts"] if kind == "jointnet" else out["lf"]
            rmse = masked_errors_mm(pred, torch.from_numpy(s.verts)[None])["rmse_mm"]
            sq += rmse**2 * s.num_frames
            n += s.num_frames
    model.train()
    return math.sqrt(sq / n)


def run_variant(kind: str, name: str, train: GarmentSequences, test: GarmentSequences, args) -> dict:
    window = [f"data.burn_in={args.burn_in}", f"data.window={args.window}", f"data.stride={args.window - args.burn_in}",
              f"train.batch_size={args.batch}"]
    if kind == "jointnet":
        cfg = load_config(JointNetRunConfig, CONFIGS / "jointnet.yaml",
                          window + [f"model.loss_frames={args.loss_frames}"] + variant_overrides(name))
        cls, stage = JointNet, "stage1"
    else:
        cfg = load_config(VirtualBonesRunConfig, CONFIGS / "virtualbones.yaml", window)
        cls, stage = VirtualBones, "low"
    seed_everything(0)
    model = cls.from_data(train, cfg.model)
    if kind == "jointnet" and "no-fourier" in name.split("+"):
        model.fourier_alpha.data.zero_()
        model.fourier_alpha.requires_grad_(False)
    dataset = WindowDataset(train, cfg.data.window, cfg.data.stride, cfg.data.burn_in)
    data = batches(dataset, cfg.train.batch_size, args.steps, collate_fn(model), seed=1)
    settings = cfg.train.stage(stage)
    params = [p for p in model.stage_parameters(stage) if p.requires_grad]
    optimizer = _optimizer(params, cfg.train, settings)
    record: dict = {"loss": [], "l1_mm": [], "grad_norm": [], "max_bone_output": [], "held_out_rmse_mm": {}}
    record["config"] = {"optimizer": cfg.train.optimizer, "lr": settings.lr, "grad_clip": settings.grad_clip,
                        "batch_size": settings.batch_size, **{k: getattr(cfg.model, k, None) for k in
                        ("fourier", "bone_init", "fourier_scale", "gru_hidden", "features", "bone_mlp", "loss_frames")}}
    if kind == "jointnet":
        last = model.bone_mlp[-1]
        hook = last.register_forward_hook(lambda m, i, o: record["max_bone_output"].append(float(o.detach().abs().max())))
    record["held_out_rmse_mm"][0] = held_out_rmse(model, test, kind)
    start = time.perf_counter()
    for step, batch in enumerate(data, 1):
        model.zero_grad(set_to_none=True)
        loss, terms = model.training_loss(batch, stage)
        if not torch.isfinite(loss):
            record["stopped"] = f"loss {loss.item()} at step {step}"
            break
        loss.backward()
        norm = torch.nn.utils.clip_grad_norm_(params, settings.grad_clip if settings.grad_clip else float("inf"))
        optimizer.step()
        record["loss"].append(loss.item())
        record["l1_mm"].append(float(terms["l1_mm"]) if "l1_mm" in terms else 1e3 * float(terms["vertex"]))
        record["grad_norm"].append(float(norm))
        if step % args.eval_every == 0 or step == args.steps:
            record["held_out_rmse_mm"][step] = held_out_rmse(model, test, kind)
            print(f"{kind}/{name} step {step}: loss {np.mean(record['loss'][-args.eval_every:]):.4g}, "
                  f"held-out {record['held_out_rmse_mm'][step]:.1f} mm ({time.perf_counter() - start:.0f} s)", flush=True)
    if kind == "jointnet":
        hook.remove()
    losses = record["loss"]
    k = max(1, min(5, len(losses) // 4))
    record["summary"] = {
        "loss_first": float(np.mean(losses[:k])), "loss_last": float(np.mean(losses[-k:])),
        "loss_max": float(np.max(losses)),
        "held_out_start_mm": record["held_out_rmse_mm"][0],
        "held_out_end_mm": record["held_out_rmse_mm"][max(record["held_out_rmse_mm"])],
        "held_out_max_mm": max(record["held_out_rmse_mm"].values()),
        "max_bone_output": max(record["max_bone_output"], default=None),
        "steps": len(losses), "seconds": time.perf_counter() - start,
        "parameters": sum(p.numel() for p in params),
    }
    return record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True)
    parser.add_argument("--garment", required=True)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--eval-every", type=int, default=20)
    parser.add_argument("--batch", type=int, default=8, help="windows per batch (paper: 8)")
    parser.add_argument("--window", type=int, default=30, help="frames per window")
    parser.add_argument("--burn-in", type=int, default=5)
    parser.add_argument("--loss-frames", type=int, default=8, help="JointNet model.loss_frames (0: all)")
    parser.add_argument("--variants", default="paper,rmsprop-torch+init-torch+add")
    parser.add_argument("--virtualbones", action="store_true", help="also train VirtualBones' low-frequency module")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--name", default="jointnet-stability")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    train = GarmentSequences(args.data, args.garment, "train", bones=True, body=False)
    test = GarmentSequences(args.data, args.garment, "test", bones=False, body=False)
    results = {"data": str(Path(args.data).resolve()), "garment": args.garment, "machine": machine(),
               "settings": {k: getattr(args, k) for k in ("steps", "batch", "window", "burn_in", "loss_frames", "threads")},
               "train_sequences": [s.name for s in train.sequences], "test_sequences": [s.name for s in test.sequences],
               "variants": {}}
    runs = [("jointnet", v) for v in args.variants.split(",") if v] + [("virtualbones", "low")] * args.virtualbones
    for kind, name in runs:
        results["variants"][f"{kind}/{name}"] = run_variant(kind, name, train, test, args)
        partial = Path(__file__).resolve().parents[1] / "results" / f"{args.name}.json"  # kept if a later variant fails
        partial.write_text(json.dumps({"benchmark": args.name, "partial": True, "results": results}, indent=2))
    for key, r in results["variants"].items():
        s = r["summary"]
        print(f"{key:40s} loss {s['loss_first']:.4g} -> {s['loss_last']:.4g} (max {s['loss_max']:.4g}); held-out "
              f"{s['held_out_start_mm']:.1f} -> {s['held_out_end_mm']:.1f} mm (max {s['held_out_max_mm']:.1f})")
    save_results(args.name, results)


if __name__ == "__main__":
    main()
