"""Cloth simulation speed and quality: milliseconds per frame for skirts of about 1k, 3k, 6k and 12k
vertices on the default body doing a procedural spin, with and without self-collision, with their
penetration and strain statistics; optionally the wall time to simulate a whole plan.

Run: .venv/bin/python benchmarks/simulation.py [--seconds 2] [--sizes 1000,3000,6000,12000]
         [--plan configs/datasets/bench.yaml --workers 2]
(writes benchmarks/results/simulation.json, and simulation-plan-<plan>.json for --plan)
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

import numpy as np  # noqa: E402

from loosefit.body import AnnyBody  # noqa: E402
from loosefit.data import DatasetStore  # noqa: E402
from loosefit.garment import make_garment  # noqa: E402
from loosefit.motion.procedural import generate  # noqa: E402
from loosefit.sim import SimParams, simulate_sequence  # noqa: E402
from loosefit.simulate import run_plan

SKIRT = {"flare": 25.0, "length": 0.55}
STATS = ("ms_per_frame", "quality", "penetration", "penetration_max", "penetration_depth", "max_strain", "strain_p99",
         "pinned_drift")


def skirt_of_size(body, vertices: int):
    """The benchmark skirt remeshed to about ``vertices`` vertices (edge length from the area, refined once)."""
    edge = 0.02
    for _ in range(2):
        garment = make_garment("skirt", body, seed=0, edge_length=edge, **SKIRT)
        edge = min(0.06, max(0.006, edge * (len(garment.verts) / vertices) ** 0.5))
    return garment


def sizes(body, targets: list[int], seconds: float) -> list[dict]:
    motion = generate("spin", seconds, 0, body)
    rows = []
    for target in targets:
        garment = skirt_of_size(body, target)
        for self_collision in (False, True):
            result = simulate_sequence(garment, body, motion, SimParams(self_collision=self_collision))
            row = {"target_vertices": target, "vertices": len(garment.verts), "self_collision": self_collision,
                   "frames": motion.num_frames, "status": result.status, "reason": result.reason,
                   **{key: result.stats[key] for key in STATS}}
            rows.append(row)
            print(f"{len(garment.verts):6d} vertices self={self_collision!s:5} {row['ms_per_frame']:7.1f} ms/frame "
                  f"({row['quality']} steps) "
                  f"penetration {row['penetration']:.3%} (worst {row['penetration_max']:.3%}) "
                  f"strain p99 {row['strain_p99']:.3f} {result.status} {result.reason}", flush=True)
    return rows


def plan_time(plan: str, workers: int, out: str | None = None) -> dict:
    """Simulate ``plan`` (into ``out``, resuming it, or a temporary store) and summarise time and quality."""
    with tempfile.TemporaryDirectory(prefix="loosefit-bench-") as tmp:
        store_path = Path(out) if out else Path(tmp) / "data.zarr"
        start = time.perf_counter()
        summary = run_plan(plan, store_path, workers=workers)
        wall = time.perf_counter() - start
        store = DatasetStore.open(store_path)
        stats = [store.sequence(n).stats for n in store.sequence_names(status=None)]
    sequences = summary["sequences"].values()

    def spread(key):
        values = np.array([s[key] for s in stats if s.get(key) is not None], float)
        if not len(values):
            return None
        return {"mean": float(values.mean()), "median": float(np.median(values)), "max": float(values.max())}

    return {"plan": plan, "workers": workers, "wall_s": wall, "jobs": summary["jobs"], "skipped": summary["skipped"],
            "ok": summary["ok"], "failed": summary["failed"], "crashed": summary["crashed"],
            "ms_per_frame_mean": sum(s["ms_per_frame"] or 0 for s in sequences) / max(1, len(sequences)),
            "penetration": spread("penetration"), "penetration_max": spread("penetration_max"),
            "max_strain": spread("max_strain"), "strain_p99": spread("strain_p99"), "pinned_drift": spread("pinned_drift"),
            "failures": {k: s["reason"] for k, s in summary["sequences"].items() if s["status"] != "ok"}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="length of the spin (plus a 1 s pre-roll)")
    parser.add_argument("--sizes", default="1000,3000,6000,12000", help="target vertex counts ('' to skip)")
    parser.add_argument("--plan", help="also time simulating this plan (e.g. configs/datasets/bench.yaml)")
    parser.add_argument("--workers", type=int, default=1, help="Ray workers for --plan")
    parser.add_argument("--out", default=None, help="keep (and resume) the plan's dataset here instead of a temporary folder")
    args = parser.parse_args()
    targets = [int(s) for s in args.sizes.split(",") if s.strip()]
    if targets:
        load = os.getloadavg()
        rows = sizes(AnnyBody(), targets, args.seconds)
        results = {"load_average": [load, os.getloadavg()], "params": SimParams().to_dict(), "sizes": rows}
        save_results("simulation", results)
    if args.plan:
        load = os.getloadavg()
        timing = plan_time(args.plan, args.workers, args.out)
        save_results(f"simulation-plan-{Path(args.plan).stem}", {"load_average": [load, os.getloadavg()], **timing})


if __name__ == "__main__":
    main()
