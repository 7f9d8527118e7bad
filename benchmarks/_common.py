"""Shared helpers for benchmark scripts: machine description and atomic JSON results."""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

from loosefit.paths import atomic_path

RESULTS = Path(__file__).resolve().parent / "results"

#: The CPU-sized networks that the speed and accuracy benchmarks share (the paper sizes train only on a
#: GPU in reasonable time and miss the streaming targets on a CPU): VirtualBones with its per-vertex global
#: layer factorised through 64 channels, JointNet with narrower GRUs, features, bone MLP and PSD basis.
CPU_MODEL = {
    "virtualbones": ["model.global_rank=64"],
    "jointnet": ["model.gru_hidden=256", "model.features=256", "model.bone_mlp=[512,512,256]", "model.psd_shapes=32"],
}


def machine() -> dict:
    """What the numbers were measured on."""
    import torch

    return {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpus": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
    }


def plan_case(plan, garment: str, motion: str, frames: int | None = None):
    """``(body, garment, motion)``: a plan's (a :class:`~loosefit.sim.plan.Plan`) garment and motion on the average
    Anny body, as its simulation makes them; the motion's first ``frames`` only when given."""
    from loosefit.body import AnnyShape
    from loosefit.simulate import load_plan_garment, load_plan_motion, plan_body

    shape = tuple(AnnyShape().to_array().tolist())
    played = load_plan_motion(plan, motion)
    return plan_body(shape), load_plan_garment(plan, garment, shape), played.slice(0, frames)


def save_results(name: str, results: dict) -> Path:
    """Write ``benchmarks/results/<name>.json`` atomically and print it."""
    path = RESULTS / f"{name}.json"
    payload = {"benchmark": name, "machine": machine(), "results": results}
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(payload, indent=2))
    print(json.dumps(payload, indent=2))
    return path
