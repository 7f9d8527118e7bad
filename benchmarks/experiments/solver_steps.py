"""One sequence of a plan simulated at several solver-step counts: does a fast limb come through the cloth?

The adaptive rule (``loosefit.sim.collider.steps_per_frame``) sizes the steps a frame by the fastest collider
vertex near the garment at the start; a limb that starts farther away (legs under a long dress) and moves fast
later (a kick) can cross the cloth between two steps. This runs the plan's garment on the first ``--frames``
frames of one of its motions at each ``--steps`` (``0``: the rule's own count) and saves the quality gate's
statistics for each, so that the counts can be compared on the frames where it happens::

    .venv/bin/python benchmarks/experiments/solver_steps.py configs/datasets/bench-large.yaml --garment dress --motion kick-1 \\
        --frames 160 --steps 0,24 --name solver-steps-dress-kick1

Output: ``benchmarks/results/<name>.json``; per step count the gate's status and reason, the steps used,
the 99th-percentile edge strain, the share of vertices inside the body and the deepest point, ms a frame.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common
from _common import plan_case, save_results  # noqa: E402

from loosefit.sim.plan import load_plan  # noqa: E402
from loosefit.sim.sequence import simulate_sequence  # noqa: E402

KEYS = ("quality", "strain_p99", "max_strain", "penetration", "penetration_max", "penetration_depth", "ms_per_frame",
        "wall_s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plan")
    ap.add_argument("--garment", required=True)
    ap.add_argument("--motion", required=True)
    ap.add_argument("--params", default="default", help="the plan's sim_params set the runs start from")
    ap.add_argument("--frames", type=int, default=None, help="the motion's first frames only")
    ap.add_argument("--steps", default="0", help="comma-separated steps a frame; 0: the adaptive rule's")
    ap.add_argument("--name", default="solver-steps")
    args = ap.parse_args()

    plan = load_plan(args.plan)
    body, garment, motion = plan_case(plan, args.garment, args.motion, args.frames)
    base = plan.sim_params[args.params]
    runs = {}
    for steps in (int(s) for s in args.steps.split(",")):
        params = base if steps == 0 else dataclasses.replace(base, quality=steps, adaptive_quality=False)
        result = simulate_sequence(garment, body, motion, params, gate=plan.gate)
        runs["rule" if steps == 0 else str(steps)] = {"status": result.status, "reason": result.reason,
                                                       **{k: result.stats[k] for k in KEYS}}
        print(runs, flush=True)
    save_results(args.name, {"plan": args.plan, "garment": args.garment, "motion": args.motion, "params": args.params,
                             "frames": motion.num_frames, "runs": runs})


if __name__ == "__main__":
    main()
