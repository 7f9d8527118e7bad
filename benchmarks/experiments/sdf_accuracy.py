"""How good a body SDF network is where collision handling uses it: on the garment vertices a trained
garment model puts near or inside the body, against libigl's exact signed distance to the posed
collision proxy.

For each ``--sdf-runs`` network and each ``--sequences`` sequence of ``--data`` (the garment animated by
``--run`` from its rest mesh, every ``--every``-th frame):

- ``inside_pct``: % of garment vertices deeper than 1 mm inside the proxy (exact);
- ``sign_recall_pct``: % of those the network also puts inside (``S < 0``): the vertices SwinGar Eq. 10 can move;
- ``near_mean_abs_mm``: mean ``|S - S_exact|`` over the vertices within 20 mm of the surface;
- ``inside_median_cos``, ``inside_cos_below_half_pct``: agreement of the network's gradient with the exact
  one (cosine) at the inside vertices: the direction Eq. 10 moves them in;
- ``inside_depth_ratio``: mean ``|S| / |S_exact|`` at the inside vertices (1: the right distance).

Run: .venv/bin/python benchmarks/experiments/sdf_accuracy.py --data G.zarr --run RUN --sdf-runs SDF1,SDF2
         --sequences NAME,NAME [--every 20] [--name sdf-accuracy]
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import save_results  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.body import AnnyBody, AnnyShape  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.geometry.signed_distance import BodySDF  # noqa: E402
from loosefit.models.collision import (SDF_FILE, ExactSDF, FramedSDF, load_body_sdf,  # noqa: E402
                                       motion_sdf_inputs, value_and_gradient_fn)

INSIDE_M = 0.001  # the collision benchmark's tolerance
NEAR_M = 0.02


def field(sdf, points: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    """Values ``(N,)`` and gradients ``(N, 3)`` of an SDF function at ``points (N, 3)``."""
    values, gradient = value_and_gradient_fn(sdf, points)
    return values.detach().numpy(), gradient(torch.arange(len(points))).detach().numpy()


def sequence_accuracy(store: DatasetStore, name: str, run: Path, nets: dict, every: int) -> dict:
    """{network: metrics} on one sequence (see the module doc)."""
    seq = store.sequence(name)
    motion = store.motion(seq.motion)
    body = AnnyBody(AnnyShape.from_array(store.body(seq.body)), rig=motion.rig)
    verts = Animator(run, garment=store.garment(seq.garment), body=body).animate(motion)
    proxy = body.collision_proxy()
    posed = proxy.pose(motion).verts
    code, rot, origin = motion_sdf_inputs(body, motion, bone_frames=True)  # the bone frames follow the plain code
    codes = {label: code[:, :net.code_size] for label, net in nets.items()}
    per_net = {label: [] for label in nets}
    for t in range(0, len(verts), every):
        x = torch.from_numpy(np.ascontiguousarray(verts[t], np.float32))
        exact, exact_grad = field(ExactSDF(BodySDF(posed[t], proxy.faces)), x)
        inside, near = exact < -INSIDE_M, np.abs(exact) < NEAR_M
        for label, net in nets.items():
            value, grad = field(FramedSDF(net.bind(codes[label][t]), rot[t], origin[t]), x)
            cos = (grad * exact_grad).sum(-1) / np.maximum(
                np.linalg.norm(grad, axis=-1) * np.linalg.norm(exact_grad, axis=-1), 1e-12)
            per_net[label].append({
                "inside_pct": 100 * inside.mean(),
                "sign_recall_pct": 100 * (value[inside] < 0).mean() if inside.any() else np.nan,
                "near_mean_abs_mm": 1e3 * np.abs(value - exact)[near].mean() if near.any() else np.nan,
                "inside_median_cos": np.median(cos[inside]) if inside.any() else np.nan,
                "inside_cos_below_half_pct": 100 * (cos[inside] < 0.5).mean() if inside.any() else np.nan,
                "inside_depth_ratio": (np.abs(value[inside]) / np.abs(exact[inside])).mean() if inside.any() else np.nan,
            })
    return {label: {k: float(np.nanmean([f[k] for f in frames])) for k in frames[0]} for label, frames in per_net.items()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, required=True)
    p.add_argument("--run", type=Path, required=True, help="the garment model whose vertices are tested (e.g. SwinGar)")
    p.add_argument("--sdf-runs", required=True, help="comma-separated body SDF run folders")
    p.add_argument("--sequences", required=True, help="comma-separated sequence names of --data")
    p.add_argument("--every", type=int, default=20, help="every n-th frame")
    p.add_argument("--name", default="sdf-accuracy")
    args = p.parse_args()
    if args.every < 1:
        p.error("--every must be >= 1")
    store = DatasetStore.open(args.data)
    nets = {Path(r).name: load_body_sdf(Path(r) / SDF_FILE).eval() for r in args.sdf_runs.split(",") if r}
    results = {"data": str(args.data), "run": str(args.run), "every": args.every, "inside_m": INSIDE_M, "near_m": NEAR_M,
               "sdf_runs": args.sdf_runs.split(","), "sequences": {}}
    for name in args.sequences.split(","):
        results["sequences"][name] = sequence_accuracy(store, name, args.run, nets, args.every)
        for label, m in results["sequences"][name].items():
            print(f"{name} {label}: " + ", ".join(f"{k} {v:.3g}" for k, v in m.items()), flush=True)
    save_results(args.name, results)


if __name__ == "__main__":
    main()
