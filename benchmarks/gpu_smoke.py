"""Every method trained and animated on one device, end to end: the GPU path's smoke check.

For each method of ``--methods`` (VirtualBones, JointNet, SwinGar, FitGar), on a small simulated and prepared
store (``--store``; ``scripts/gpu_bundle.py`` makes one: a skirt and a dress on the average Anny body, walk and
spin for training, sway held out):

1. train about ``--steps`` optimiser steps, validating on the held-out sway (the store's test split: a smoke
   check selects nothing by it), through :func:`loosefit.training.train_model` (what ``loosefit
   train`` runs), at the papers' sizes (``--size paper``: ``configs/models/<method>.yaml``) or tiny ones (``--size
   tiny``, for a CPU check of this script), on ``--device``;
2. load the run folder and animate a motion it never saw on the same device, twice: batched (every frame in as
   few passes as the animator takes) and streaming (one frame a call, the state carried; FitGar, a static
   method, one frame a pass), and compare the two.

Reported per method: optimiser steps a second (overall, and steady: without each stage's first epoch and its
last, which validates and writes), peak device memory (CUDA: ``max_memory_allocated``; CPU: the process's
peak resident set), the loss's first and last values, validation metrics, milliseconds a frame batched and
streaming, and the largest stream/batch difference in metres (float32 round-off: microns). A method that fails
is recorded with its error and the others still run; the exit status is 1 then.

Run: .venv/bin/python benchmarks/gpu_smoke.py --store STORE.zarr [--device cuda] [--size paper|tiny]
         [--steps 240] [--methods virtualbones,jointnet,swingar,fitgar] [--name gpu-smoke]
(writes benchmarks/results/<name>.json after every method)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import shutil
import sys
import time
import traceback
from pathlib import Path

import numpy as np
import torch
import yaml

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs" / "models"
RESULTS = ROOT / "benchmarks" / "results"

#: Overrides every run takes: no progress bar, no tensorboard, no checkpoint or validation before a stage's end.
COMMON = ["train.progress=false", "train.tensorboard=false", "train.checkpoint_every=100000",
          "train.validate_every=100000"]

#: Per method: the store garment a per-garment method trains on (None: every garment), its stages, short
#: overlapping windows (many optimiser steps an epoch) and, for ``--size tiny``, small networks.
METHODS = {
    "virtualbones": {"garment": "skirt+average", "stages": ["low", "high"], "batch": 8,
                     "data": ["data.window=16", "data.stride=2", "data.burn_in=4"],
                     "tiny": ["model.lf_hidden=16", "model.hf_hidden=16", "model.edge_channels=[8]"]},
    "jointnet": {"garment": "skirt+average", "stages": ["stage1", "stage2"], "batch": 8,
                 "data": ["data.window=16", "data.stride=2", "data.burn_in=4"],
                 "tiny": ["model.gru_hidden=16", "model.features=16", "model.bone_mlp=[16]", "model.psd_mlp=[16]",
                          "model.psd_shapes=4"]},
    "swingar": {"garment": None, "stages": ["supervised", "all"], "batch": 8,
                "data": ["data.window=16", "data.stride=4"],
                "tiny": ["model.graph_hidden=[8,8]", "model.graph_heads=[2,2]", "model.shape_mlp=[8,8]",
                         "model.motion_hidden=8", "model.motion_frames=8", "model.body_mlp=[8,8]",
                         "model.state_hidden=8", "model.state_heads=1", "model.blend_hidden=[8,8]",
                         "model.blend_heads=1", "model.corrective_hidden=8", "model.corrective_heads=1",
                         "model.corrective_layers=[8,3]", "model.descriptor_samples=64"]},
    "fitgar": {"garment": None, "stages": ["coarse", "detail"], "batch": 8,
               "data": ["data.frame_stride=2"],
               "tiny": ["model.heads=2", "model.coarse_first=8", "model.coarse_blocks=[16,8]", "model.coarse_dense=[8]",
                        "model.parser=[16,16]", "model.detail_first=16", "model.detail_blocks=[8,8,8,8]",
                        "model.detail_dense=[8]"]},
}


def count_windows(lengths: list[int], window: int, stride: int, burn_in: int | None) -> int:
    """How many training windows the sequence datasets cut from sequences of these frame counts."""
    n = 0
    for T in lengths:
        starts = list(range(0, max(T - window, 0) + 1, stride))
        if starts[-1] + window < T:
            starts.append(T - window)
        n += sum(1 for s in starts if burn_in is None or T - s > burn_in)
    return n


def steps_per_epoch(store: Path, method: str) -> int:
    """Optimiser steps in one epoch of ``method``'s training on ``store``."""
    from loosefit.data.store import DatasetStore

    spec = METHODS[method]
    st = DatasetStore.open(store, mode="r")
    names = st.sequence_names(split="train")
    if spec["garment"] is not None:
        names = [n for n in names if st.sequence(n).garment == spec["garment"]]
    lengths = [int(st.sequence(n).verts.shape[0]) for n in names]
    opts = dict(o.split("=", 1) for o in spec["data"])
    if method == "fitgar":
        items = sum(len(range(0, T, int(opts["data.frame_stride"]))) for T in lengths)
    else:
        burn = int(opts["data.burn_in"]) if "data.burn_in" in opts else None
        items = count_windows(lengths, int(opts["data.window"]), int(opts["data.stride"]), burn)
    return math.ceil(items / spec["batch"])


def merged_config(method: str, overrides: list[str], work: Path) -> Path:
    """``configs/models/<method>.yaml`` with ``overrides`` merged in, as one file (coupled sizes, such as
    SwinGar's widths and heads, are checked together rather than one override at a time)."""
    cfg = yaml.safe_load((CONFIGS / f"{method}.yaml").read_text())
    for text in overrides:
        key, value = text.split("=", 1)
        *parents, last = key.split(".")
        node = cfg
        for p in parents:
            node = node.setdefault(p, {})
        node[last] = yaml.safe_load(value)
    work.mkdir(parents=True, exist_ok=True)
    path = work / f"{method}.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def sync(device: str) -> None:
    if device == "cuda":
        torch.cuda.synchronize()


def peak_memory_mib(device: str) -> float:
    """Peak device memory since the last reset (CUDA) or the process's peak resident set (CPU), MiB."""
    if device == "cuda":
        return torch.cuda.max_memory_allocated() / 2 ** 20
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def steady_rate(history: list[dict], epochs: int) -> tuple[float | None, int]:
    """Steps a second over the epochs that neither start a stage nor end it (those build or validate)."""
    steps = seconds = 0.0
    prev_step, prev_stage, k = 0, None, 0
    for r in history:
        k = k + 1 if r["stage"] == prev_stage else 1
        if k > 1 and r["epoch"] < epochs:
            steps += r["step"] - prev_step
            seconds += r["seconds"]
        prev_step, prev_stage = r["step"], r["stage"]
    return (steps / seconds if seconds else None), int(steps)


def timed(device: str, fn):
    sync(device)
    t = time.perf_counter()
    out = fn()
    sync(device)
    return out, time.perf_counter() - t


def animate_both(method: str, run: Path, store: Path, device: str, motion) -> dict:
    """Animate ``motion`` from the run folder batched and streaming; their speeds and largest difference."""
    from loosefit.animate import Animator
    from loosefit.animate_any import AnyGarmentAnimator
    from loosefit.body import AnnyBody
    from loosefit.data.store import DatasetStore

    T = motion.num_frames
    if method == "fitgar":
        st = DatasetStore.open(store, mode="r")
        g = st.garment("skirt+average")
        animator = AnyGarmentAnimator(run, device=device, frames_per_pass=T)
        pair = animator.pair(g.verts, g.faces, AnnyBody())
        animator.animate(pair, motion)  # warm-up
        batch, s_batch = timed(device, lambda: animator.animate(pair, motion))
        animator.frames_per_pass = 1
        stream, s_stream = timed(device, lambda: animator.animate(pair, motion))
    else:
        garment = DatasetStore.open(store, mode="r").garment("skirt+average") if method == "swingar" else None
        animator = Animator(run, garment=garment, device=device)
        animator.animate(motion)  # warm-up
        batch, s_batch = timed(device, lambda: animator.animate(motion))

        def streamed():
            stream = animator.stream()
            return np.stack([stream.step(motion.rotations[f], motion.translation[f]) for f in range(T)])

        stream, s_stream = timed(device, streamed)
    return {"frames": int(T), "vertices": int(batch.shape[1]), "finite": bool(np.isfinite(batch).all() and
                                                                             np.isfinite(stream).all()),
            "batch_ms_per_frame": 1e3 * s_batch / T, "stream_ms_per_frame": 1e3 * s_stream / T,
            "stream_vs_batch_max_abs_m": float(np.abs(stream - batch).max())}


def run_method(method: str, a) -> dict:
    from loosefit.body import AnnyBody
    from loosefit.motion.procedural import generate
    from loosefit.training import train_model

    spec = METHODS[method]
    per_epoch = steps_per_epoch(a.store, method)
    epochs = max(2, round(a.steps / len(spec["stages"]) / per_epoch))
    overrides = list(COMMON) + spec["data"] + [f"train.device={a.device}", f"train.threads={a.threads}",
                                                f"train.batch_size={spec['batch']}"]
    overrides += [f"train.stages.{s}.epochs={epochs}" for s in spec["stages"]]
    if a.size == "tiny":
        overrides += spec["tiny"]
    out = a.work / method
    shutil.rmtree(out, ignore_errors=True)
    config = merged_config(method, overrides, a.work)
    row = {"method": method, "garment": spec["garment"], "size": a.size, "device": a.device,
           "steps_per_epoch": per_epoch, "epochs_per_stage": epochs}
    print(f"== {method}: {epochs} epochs x {len(spec['stages'])} stages x {per_epoch} steps", flush=True)
    if a.device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    result, wall = timed(a.device, lambda: train_model(method, a.store, spec["garment"], out, config=config,
                                                                   val_split="test"))
    hist = result.history
    rate, steady_steps = steady_rate(hist, epochs)
    row.update({"train_wall_s": wall, "steps": result.global_step, "parameters": result.parameter_count,
                "steps_per_s": result.global_step / result.wall_s, "steps_per_s_steady": rate,
                "steady_steps": steady_steps, "train_peak_memory_mib": peak_memory_mib(a.device),
                "loss_first": hist[0].get("train_loss"), "loss_last": hist[-1].get("train_loss"),
                "finite": all(math.isfinite(r.get("train_loss", float("nan"))) for r in hist),
                "val_metrics": result.val_metrics,
                "history": [{k: (round(v, 6) if isinstance(v, float) else v) for k, v in r.items()} for r in hist]})
    print(f"   {result.global_step} steps in {result.wall_s:.1f} s ({row['steps_per_s']:.1f}/s, steady "
          f"{rate or float('nan'):.1f}/s); loss {row['loss_first']:.4g} -> {row['loss_last']:.4g}; "
          f"val {({k: round(v, 2) for k, v in result.val_metrics.items()})}", flush=True)
    motion = generate("walk", a.seconds, 7, AnnyBody())
    if a.device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    row["animate"] = animate_both(method, out, a.store, a.device, motion)
    row["animate"]["peak_memory_mib"] = peak_memory_mib(a.device)
    an = row["animate"]
    print(f"   animated {an['frames']} x {an['vertices']}: batch {an['batch_ms_per_frame']:.2f} ms/frame, stream "
          f"{an['stream_ms_per_frame']:.2f} ms/frame, max |stream - batch| {an['stream_vs_batch_max_abs_m']:.2e} m",
          flush=True)
    return row


def environment(device: str) -> dict:
    env = {"torch": torch.__version__, "python": sys.version.split()[0], "cpus": os.cpu_count()}
    if device == "cuda":
        env.update(cuda=torch.version.cuda, gpu=torch.cuda.get_device_name(0))
    return env


def save(path: Path, results: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(results, indent=2, default=str))
    tmp.replace(path)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--store", type=Path, required=True, help="a small simulated, prepared store (scripts/gpu_bundle.py)")
    p.add_argument("--device", default="cuda", choices=["cpu", "cuda"])
    p.add_argument("--methods", default="virtualbones,jointnet,swingar,fitgar")
    p.add_argument("--steps", type=int, default=240, help="about this many optimiser steps per method")
    p.add_argument("--size", default="paper", choices=["paper", "tiny"])
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--seconds", type=float, default=2.0, help="length of the animated motion")
    p.add_argument("--work", type=Path, default=Path("/tmp/loosefit-gpu-smoke"))
    p.add_argument("--name", default="gpu-smoke")
    p.add_argument("--out", type=Path, default=None, help="the JSON (default benchmarks/results/<name>.json)")
    a = p.parse_args()
    if a.device == "cuda" and not torch.cuda.is_available():
        print("gpu_smoke: error: --device cuda but torch sees no CUDA device", file=sys.stderr)
        return 2
    path = a.out or RESULTS / f"{a.name}.json"
    results = {"benchmark": "gpu-smoke", "settings": {k: str(v) for k, v in vars(a).items()},
               "env": environment(a.device), "methods": {}}
    failed = []
    for method in [m for m in a.methods.split(",") if m]:
        start = time.perf_counter()
        results["methods"][method] = {"error": "started, did not finish (timed out or killed)"}
        save(path, results)
        try:
            results["methods"][method] = run_method(method, a)
        except Exception as e:  # one method failing must not hide the others
            traceback.print_exc()
            results["methods"][method] = {"error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc()}
            failed.append(method)
        results["methods"][method]["method_wall_s"] = time.perf_counter() - start
        save(path, results)
    print(f"wrote {path}; failed: {failed or 'none'}", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
