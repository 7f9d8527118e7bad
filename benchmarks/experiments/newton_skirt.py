"""Newton backend on the bench skirt: ms/frame, the quality gate, the 10-micrometre noise spread, one rendered frame.

A measurement, not a test. Run from the project root:
  OMP_NUM_THREADS=1 .venv/bin/python benchmarks/experiments/newton_skirt.py --seconds 2 [--noise] [--set KEY=VALUE ...]
Writes ``benchmarks/results/newton-skirt-walk.json``, the simulated sequence as ``/tmp/NAME.npz``
and a PNG of one frame (``--png``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common
from _common import plan_case  # noqa: E402

from loosefit.sim import simulate_sequence  # noqa: E402
from loosefit.sim.plan import load_plan  # noqa: E402
from loosefit.sim.sequence import save_result  # noqa: E402

RESULTS = Path(__file__).resolve().parents[1] / "results"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--plan", default="configs/datasets/bench.yaml")
    ap.add_argument("--garment", default="skirt")
    ap.add_argument("--motion", default="walk-1")
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--noise", action="store_true", help="also run with 10 um start noise and report the spread")
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--name", default="newton-skirt-walk")
    ap.add_argument("--png", type=int, default=45, help="frame to render to results/NAME.png (-1: none)")
    a = ap.parse_args()

    plan = load_plan(a.plan)
    body, garment, motion = plan_case(plan, a.garment, a.motion)
    motion = motion.slice(0, int(a.seconds * motion.fps))
    params = plan.sim_params[next(iter(plan.sim_params))].with_overrides(["backend=newton", *a.set])

    start = time.perf_counter()
    result = simulate_sequence(garment, body, motion, params)
    report = {
        "garment": a.garment, "motion": a.motion, "seconds": a.seconds, "garment_verts": len(garment.verts),
        "params": params.to_dict(), "status": result.status, "reason": result.reason,
        "stats": result.stats, "wall_s": time.perf_counter() - start,
    }
    print(json.dumps({k: report[k] for k in ("status", "reason")}), json.dumps(result.stats), flush=True)
    RESULTS.mkdir(exist_ok=True)
    npz = Path("/tmp") / f"{a.name}.npz"
    save_result(npz, result, garment.faces, body.faces, motion.fps)
    report["sequence"] = str(npz)
    if 0 <= a.png < len(result.verts):
        from loosefit.viz.inputs import load_panels
        from loosefit.viz.render import render_frames, save_png

        save_png(RESULTS / f"{a.name}.png", render_frames(load_panels(npz), size=(800, 600), frames=[a.png])[0])

    if a.noise:
        noisy = dataclasses.replace(garment, verts=(garment.verts + np.random.default_rng(0).normal(
            0, 1e-5, garment.verts.shape)).astype(np.float32))
        other = simulate_sequence(noisy, body, motion, params).verts
        sq = ((result.verts - other) ** 2).sum(-1)
        half = int(round(motion.fps / 2))
        report["noise_rmse_mm"] = float(np.sqrt(sq.mean()) * 1e3)
        report["noise_rmse_mm_per_half_second"] = [
            round(float(np.sqrt(sq[i:i + half].mean()) * 1e3), 2) for i in range(0, len(sq), half)]
        print("noise spread", report["noise_rmse_mm"], report["noise_rmse_mm_per_half_second"], flush=True)
    (RESULTS / f"{a.name}.json").write_text(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
