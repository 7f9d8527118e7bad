"""How far apart two equally valid simulations of nearly the same motion are: the floor under any
held-out accuracy number.

One garment of a plan is simulated on one of its motions twice as is (the simulator must repeat
itself exactly), then once per ``--degrees`` value with ``--joint`` turned by that angle about a
slowly turning random axis (the robustness test's perturbation at a fixed angle). Each perturbed run is compared
with the unperturbed one: RMSE over the garment, RMSE per second of motion, and the mean change of
the vertices below the knees. With ``--data`` (a store simulated from the same plan), the unperturbed
run is also compared with the stored sequence, which tells whether the store still matches the code.

A learned model is deterministic: when a nudge of a fraction of a degree to an arm moves the simulated
hem by centimetres, no model can follow both simulations, and held-out RMSE stays near this spread
however much it trains.

Run: .venv/bin/python benchmarks/sensitivity.py --plan configs/datasets/bench.yaml --garment skirt
         --motion walk-1 [--joint LeftArm] [--degrees 0.1,0.5,2] [--data DATA.zarr] [--sim-params NAME]
         [--set air_drag=0.5 ...] [--seconds 4] [--name sensitivity-skirt]
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402
from accuracy import KNEES, perturb_joint  # noqa: E402

import numpy as np  # noqa: E402

from loosefit.body import AnnyShape  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.errors import InputError  # noqa: E402
from loosefit.sim import simulate_sequence  # noqa: E402
from loosefit.sim.plan import load_plan  # noqa: E402
from loosefit.sim.runner import load_plan_garment, load_plan_motion, plan_body  # noqa: E402


def difference(a: np.ndarray, b: np.ndarray, below: np.ndarray, fps: float) -> dict:
    """RMSE (mm) of ``a`` against ``b`` ``(T, V, 3)``, overall and per second, and the mean distance (mm)
    of the vertices ``below`` the knees."""
    sq = ((a - b) ** 2).sum(-1)  # (T, V)
    per = int(round(fps))
    return {"rmse_mm": float(np.sqrt(sq.mean()) * 1e3),
            "rmse_per_second_mm": [float(np.sqrt(sq[i:i + per].mean()) * 1e3) for i in range(0, len(sq), per)],
            "mean_below_knees_mm": float(np.sqrt(sq[:, below]).mean() * 1e3)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plan", required=True, help="a dataset plan (configs/datasets/*.yaml)")
    parser.add_argument("--garment", required=True, help="a garment of the plan")
    parser.add_argument("--motion", required=True, help="a motion of the plan")
    parser.add_argument("--joint", default="LeftArm", help="the joint turned")
    parser.add_argument("--degrees", default="0.1,0.5,2", help="comma-separated constant angles, degrees")
    parser.add_argument("--data", default=None, help="a store simulated from the plan, to compare with")
    parser.add_argument("--sim-params", default=None, help="a simulation-parameter set of the plan (default: its first)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override one simulation parameter (repeatable), e.g. --set air_drag=0.5")
    parser.add_argument("--seconds", type=float, default=None, help="simulate only the motion's first seconds")
    parser.add_argument("--name", default=None, help="results name (default sensitivity-<garment>-<motion>)")
    args = parser.parse_args()
    plan = load_plan(args.plan)
    for kind, name, known in (("garment", args.garment, plan.garments), ("motion", args.motion, plan.motions)):
        if name not in known:
            raise InputError(f"{kind} {name!r} is not in the plan (it has {sorted(known)})", args.plan)
    degrees = [float(d) for d in args.degrees.split(",")]
    shape = tuple(AnnyShape().to_array().tolist())
    body = plan_body(shape)
    if args.joint not in body.joint_names:
        raise InputError(f"--joint {args.joint!r} is not a joint of the body rig ({body.joint_names})")
    garment = load_plan_garment(plan, args.garment, shape)
    motion = load_plan_motion(plan, args.motion)
    if args.seconds is not None:
        motion = motion.slice(0, max(2, int(round(args.seconds * motion.fps))))
    params_name = args.sim_params or next(iter(plan.sim_params))
    if params_name not in plan.sim_params:
        raise InputError(f"simulation-parameter set {params_name!r} is not in the plan "
                         f"(it has {sorted(plan.sim_params)})", args.plan)
    params = plan.sim_params[params_name].with_overrides(args.set)
    knee = float(np.mean([body.rest_joints()[body.joint_names.index(k)][2] for k in KNEES]))
    below = garment.verts[:, 2] < knee

    def simulate(m) -> np.ndarray:
        start = time.perf_counter()
        result = simulate_sequence(garment, body, m, params)
        print(f"{m.name}: {result.status}, {time.perf_counter() - start:.0f} s", flush=True)
        return result.verts

    runs = {"as is": simulate(motion), "as is, again": simulate(motion)}
    for d in degrees:
        nudged = perturb_joint(motion, body.joint_names.index(args.joint), (d, d), seed=0)
        runs[f"{args.joint} {d:g} deg"] = simulate(nudged)
    base = runs["as is"]
    results = {"plan": args.plan, "garment": args.garment, "motion": args.motion, "frames": motion.num_frames,
               "vertices": len(garment.verts), "vertices_below_knees": int(below.sum()), "joint": args.joint,
               "sim_params": params.to_dict(),
               "load_average_at_start": os.getloadavg(),
               "against_as_is": {k: difference(v, base, below, motion.fps) for k, v in runs.items() if k != "as is"}}
    if args.data is not None:
        store = DatasetStore.open(args.data)
        stored = next((q for q in map(store.sequence, store.sequence_names())
                       if q.garment.split("+")[0] == args.garment and q.motion == args.motion), None)
        if stored is None:
            raise InputError(f"no sequence of {args.garment} on {args.motion} in the store", args.data)
        results["stored_sequence"] = stored.name
        verts = np.asarray(stored.verts[:motion.num_frames])
        results["stored_against_as_is"] = difference(verts, base, below, motion.fps)
    for k, v in {**results["against_as_is"], "stored": results.get("stored_against_as_is")}.items():
        if v is not None:
            print(f"{k:>22}: RMSE {v['rmse_mm']:6.1f} mm, below the knees {v['mean_below_knees_mm']:6.1f} mm, "
                  f"first second {v['rmse_per_second_mm'][0]:5.1f} mm")
    save_results(args.name or f"sensitivity-{args.garment}-{args.motion}", results)


if __name__ == "__main__":
    main()
