"""Does a plan's training data cover its held-out motions? Per held-out motion, the training motions that reach its
extent (:class:`loosefit.motion_range.MotionExtent`: its largest turn in each direction, turn rate, reversals and
rise), and the training frames per garment.

A network learns the motions it is shown: a held-out jump with two full turns in flight, when the training jumps turn
at most half a turn, measures extrapolation, not accuracy. ``covered_by`` counts the training motions of the same kind
(any kind for a ``mix``) whose extent covers the held-out one; the plan is meant to give every held-out motion at least
``--least`` (3).

Run: .venv/bin/python benchmarks/experiments/coverage.py --plan configs/datasets/bench-large.yaml [--least 3] [--name NAME]
(writes benchmarks/results/<name>.json, default coverage-<plan name>)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts

from _common import save_results  # noqa: E402


def coverage(plan_path: str | Path, least: int = 3) -> dict:
    from loosefit.motion_range import MotionExtent
    from loosefit.sim.plan import ProceduralMotion, load_plan
    from loosefit.simulate import load_plan_motion

    plan = load_plan(plan_path)
    test = sorted({j.motion for j in plan.jobs if j.split == "test"})
    train = sorted({j.motion for j in plan.jobs if j.split == "train"})

    def kind(name):
        spec = plan.motion_spec(name)
        return spec.procedural if isinstance(spec, ProceduralMotion) else "file"

    extents = {m: MotionExtent.of(load_plan_motion(plan, m)) for m in test + train}
    frames = {}
    for j in plan.jobs:
        if j.split == "train":
            spec = plan.motion_spec(j.motion)
            frames[j.garment] = frames.get(j.garment, 0) + int(round(spec.seconds * 30))
    out = {"plan": str(plan_path), "least": least, "train_frames": frames, "train_motions": len(train)}
    ok = True
    for m in test:
        same = [t for t in train if kind(m) in ("mix", kind(t))]
        covering = [t for t in same if extents[t].covers(extents[m])]
        out[m] = {"kind": kind(m), "extent": extents[m].to_json(), "same_kind": len(same),
                  "covered_by": len(covering), "covering": covering}
        ok &= len(covering) >= least
        print(f"{m:12s} {kind(m):6s} {extents[m].to_json()}  covered by {len(covering)} of {len(same)}: "
              f"{' '.join(covering)}", flush=True)
    out["every_held_out_motion_covered"] = bool(ok)
    print(f"training frames per garment: {frames}; every held-out motion covered by >= {least}: {ok}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--plan", required=True)
    ap.add_argument("--least", type=int, default=3)
    ap.add_argument("--name")
    a = ap.parse_args()
    from loosefit.sim.plan import load_plan

    save_results(a.name or f"coverage-{load_plan(a.plan).name}", coverage(a.plan, a.least))


if __name__ == "__main__":
    main()
