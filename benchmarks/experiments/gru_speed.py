"""Training speed of a GRU on the CPU: torch's autograd against the hand-written back-propagation through time
(:mod:`loosefit.models.layers.gru_bptt`), at the sizes VirtualBones and JointNet train with (JointNet: torch's
kernel joint by joint, its former training path, against all joints at once by hand).

For each case: forward and backward of a loss on every output, the median of ``--repeats`` runs after two
warm-up runs, both ways, one torch thread, and the largest difference of the outputs and of every gradient
between them. With ``--store``, also one VirtualBones optimiser step of the low-frequency stage (the demo's
settings) on a prepared store, the two ways alternating so that both see the same load.

Run: .venv/bin/python benchmarks/experiments/gru_speed.py [--repeats 7] [--store STORE.zarr --garment G]
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import time
from pathlib import Path

import torch

from loosefit.models.layers import gru as gru_module
from loosefit.models.layers.gru_bptt import gru_bptt

#: (name, inputs, hidden units, batch, frames): VirtualBones' low-frequency GRU (CPU preset and paper: 600 units;
#: inputs 11 + 6 x 30 joints) over the demo's 90-frame windows and the benchmark's 64-frame ones; its high-frequency
#: GRU (80 bones x 12 inputs).
CASES = [("virtualbones low, demo windows", 191, 600, 4, 90), ("virtualbones low, 64-frame windows", 191, 600, 8, 64),
         ("virtualbones high", 960, 600, 4, 90)]
#: (name, joints, inputs, units, batch, frames): JointNet's per-joint GRUs (24 joints of the cmu_mb rig; inputs
#: 11 + 6 x (2 + 3 children)) at the CPU preset (256 units, 50-frame windows) and the demo's (128 units).
JOINT_CASES = [("jointnet, CPU preset", 24, 41, 256, 8, 50), ("jointnet, demo", 24, 41, 128, 4, 90)]


ROOT = Path(__file__).resolve().parents[2]  # the repository

def median_ms(fn, repeats: int) -> float:
    for _ in range(2):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def gru_case(inputs: int, hidden: int, batch: int, frames: int, repeats: int) -> dict:
    torch.manual_seed(0)
    gru = torch.nn.GRU(inputs, hidden, batch_first=True)
    x = torch.randn(batch, frames, inputs, requires_grad=True)

    def step(fn):
        gru.zero_grad()
        x.grad = None
        out, last = fn(gru, x)
        (out.square().mean() + last.square().mean()).backward()
        return out.detach(), [x.grad.clone()] + [p.grad.clone() for p in gru.parameters()]

    torch_out, torch_grads = step(lambda g, a: g(a))
    hand_out, hand_grads = step(gru_bptt)
    with torch.no_grad():
        forward = median_ms(lambda: gru(x), repeats)
    return {"torch_ms": median_ms(lambda: step(lambda g, a: g(a)), repeats),
            "hand_written_ms": median_ms(lambda: step(gru_bptt), repeats),
            "forward_only_ms": forward,
            "max_output_difference": float((torch_out - hand_out).abs().max()),
            "max_relative_gradient_difference": max(float((a - b).abs().max() / b.abs().max().clamp_min(1e-30))
                                                    for a, b in zip(hand_grads, torch_grads))}


def jointnet_case(joints: int, inputs: int, hidden: int, batch: int, frames: int, repeats: int) -> dict:
    """JointNet's GRUs: torch's kernel joint by joint (the former training path) against all joints by hand."""
    from loosefit.models.jointnet import JointGRU

    torch.manual_seed(0)
    gru = JointGRU(joints, inputs, hidden)
    x = torch.randn(batch, frames, joints, inputs, requires_grad=True)

    def step(order):
        gru.zero_grad()
        x.grad = None
        out, last = getattr(gru, order)(x)
        (out.square().mean() + last.square().mean()).backward()
        return out.detach(), [x.grad.clone()] + [p.grad.clone() for p in gru.parameters()]

    torch_out, torch_grads = step("joint_by_joint")
    hand_out, hand_grads = step("all_joints_by_hand")
    return {"torch_ms": median_ms(lambda: step("joint_by_joint"), repeats),
            "hand_written_ms": median_ms(lambda: step("all_joints_by_hand"), repeats),
            "max_output_difference": float((torch_out - hand_out).abs().max()),
            "max_relative_gradient_difference": max(float((a - b).abs().max() / b.abs().max().clamp_min(1e-30))
                                                    for a, b in zip(hand_grads, torch_grads))}


@contextlib.contextmanager
def torch_gru_only():
    """GRUHead as it was: torch's GRU under autograd too."""
    saved = gru_module.gru_bptt
    gru_module.gru_bptt = lambda gru, x, h=None: gru(x, h)
    try:
        yield
    finally:
        gru_module.gru_bptt = saved


def virtualbones_step(store_path: str, garment: str, repeats: int) -> dict:
    from torch.utils.data import default_collate

    from loosefit.config import load_config
    from loosefit.data.store import DatasetStore
    from loosefit.models.dataset import GarmentSequences, WindowDataset
    from loosefit.models.virtualbones import VirtualBones
    from loosefit.training import run_config_class

    store = DatasetStore.open(store_path, mode="r")
    cfg = load_config(run_config_class("virtualbones"), ROOT / "configs/models/virtualbones.yaml",
                      ["model.global_rank=64", "data.window=90", "data.stride=90", "data.burn_in=0"])
    data = GarmentSequences(store, garment, "train", bones=True)
    torch.manual_seed(0)
    model = VirtualBones.from_data(data, cfg.model)
    windows = WindowDataset(data, 90, 90, 0)
    batch = default_collate([windows[k] for k in range(min(4, len(windows)))])
    params = list(model.stage_parameters("low"))
    model.requires_grad_(False)
    for p in params:
        p.requires_grad_(True)
    optimizer = torch.optim.Adam(params, lr=1e-3)

    def step():
        loss, _ = model.training_loss(batch, "low")
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()

    # alternating, so that both see the same load on a shared machine
    hand, plain = [], []
    for _ in range(repeats):
        hand.append(median_ms(step, 1))
        with torch_gru_only():
            plain.append(median_ms(step, 1))
    hand, plain = statistics.median(hand), statistics.median(plain)
    return {"store": str(Path(store_path).resolve()), "garment": garment, "vertices": int(batch["verts"].shape[-2]),
            "batch": int(batch["verts"].shape[0]), "frames": int(batch["verts"].shape[1]),
            "torch_ms": plain, "hand_written_ms": hand}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--store", help="a prepared store for one VirtualBones training step (e.g. the demo's)")
    parser.add_argument("--garment", default="skirt+average")
    parser.add_argument("--name", default="gru-speed")
    args = parser.parse_args()
    torch.set_num_threads(1)
    results = {"threads": 1, "load_average_at_start": os.getloadavg()[0], "cases": {}}
    for name, inputs, hidden, batch, frames in CASES:
        row = {"inputs": inputs, "hidden": hidden, "batch": batch, "frames": frames,
               **gru_case(inputs, hidden, batch, frames, args.repeats)}
        results["cases"][name] = row
        print(f"{name}: torch {row['torch_ms']:.0f} ms, hand-written {row['hand_written_ms']:.0f} ms "
              f"(forward alone {row['forward_only_ms']:.0f}); largest gradient difference "
              f"{row['max_relative_gradient_difference']:.1e} relative", flush=True)
    for name, joints, inputs, hidden, batch, frames in JOINT_CASES:
        row = {"joints": joints, "inputs": inputs, "hidden": hidden, "batch": batch, "frames": frames,
               **jointnet_case(joints, inputs, hidden, batch, frames, args.repeats)}
        results["cases"][name] = row
        print(f"{name}: torch joint by joint {row['torch_ms']:.0f} ms, all joints by hand "
              f"{row['hand_written_ms']:.0f} ms; largest gradient difference "
              f"{row['max_relative_gradient_difference']:.1e} relative", flush=True)
    if args.store:
        row = results["virtualbones_low_step"] = virtualbones_step(args.store, args.garment, args.repeats)
        print(f"VirtualBones low-frequency step: torch {row['torch_ms']:.0f} ms, hand-written "
              f"{row['hand_written_ms']:.0f} ms", flush=True)
    results["load_average_at_end"] = os.getloadavg()[0]
    out = Path(__file__).resolve().parents[1] / "results" / f"{args.name}.json"
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
