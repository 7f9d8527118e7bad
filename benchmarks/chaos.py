"""How chaotic the ground truth is: what a simulated garment does under changes that should not matter.

For each garment and motion of a plan (first ``--seconds`` of the motion), one base simulation and one
per probe, each compared with the base (RMSE over the garment, per half second, and below the knees):

  noise-S   every garment vertex of the rest mesh (the start state) moved by Gaussian noise of
            ``--sigma`` metres (10 micrometres), noise seed S (``--noise-seeds``, two by default)
  steps     the base's solver steps per frame doubled (time-step convergence: N against 2N)
  nudge-D   the left arm turned by D degrees about a slowly turning axis (``--nudge-degrees``; the
            accuracy benchmark's robustness perturbation at a fixed angle)
  repeat    the base again, in another process: ``bit_identical`` and the largest difference
  mean-steps  step-count convergence of the mean run: ``--references`` K runs with start noise (seeds 1..K,
            as a store's reference runs, :func:`loosefit.simulate.perturb_start`) at the base's N solver
            steps a frame and K at 2N; the mean of each set with its base (the base, and the ``steps`` run at 2N)
            and the RMS distance between the two means, ``<garment>/<motion>/mean_steps_mm``, beside the floor
            of each set (``floor_mm`` at N, ``floor_2n_mm``: :mod:`loosefit.metrics.reference`). When the two
            means differ by much less than the floor, N steps resolve what a model can learn (the mean).
            Not run by default (2K + 1 more simulations a garment and motion): ``--probes mean-steps``

Every simulation runs in a fresh process (``--workers`` at a time), so no run reads another's cache and
``repeat`` checks reproducibility across processes. With ``--data`` (a store simulated from the plan), the
base is also compared with the stored sequence.

A learned model is deterministic: when 10 micrometres at the start or a twentieth of a degree move the hem by
centimetres, no model can follow both simulations, and held-out error stays near the spread however long it
trains. Floors (the ground-truth targets): spread at most 10 mm on a walk and 20 mm on a spin over 4 s, steps
at most 10 mm, repeat bit-identical.

Every figure is named ``<garment>/<motion>/<probe>/<measure>`` in the JSON (``skirt/walk-1/noise-0/rmse_mm``),
the mean-steps probe's ``<garment>/<motion>/<measure>`` (``skirt/spin_test/mean_steps_mm``).

Run: .venv/bin/python benchmarks/chaos.py --plan configs/datasets/bench.yaml [--garments skirt,dress]
         [--motions walk-1,spin-1,jump-1,kick-1] [--seconds 4] [--probes noise,steps,nudge,repeat]
         [--sim-params NAME] [--set KEY=VALUE ...] [--workers 2] [--name chaos-bench]
         [--sample-stride 40 --sample-offset 39]   (a held plan: the settled poses alone)
         [--references 4]   (the mean-steps probe's runs per step count)
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

import numpy as np  # noqa: E402

from loosefit.errors import InputError  # noqa: E402

#: The joint the nudge probe turns.
NUDGE_JOINT = "LeftArm"
PROBES = ("noise", "steps", "nudge", "repeat", "mean-steps")
DEFAULT_PROBES = ("noise", "steps", "nudge", "repeat")


@dataclasses.dataclass(frozen=True)
class Task:
    """One simulation of a chaos run: the plan's garment on the first ``frames`` of its motion."""

    plan: str
    garment: str
    motion: str
    frames: int
    params: dict
    noise_seed: int | None = None
    sigma: float = 0.0
    nudge_degrees: float = 0.0
    quality: int | None = None  # fixed solver steps per frame (adaptive steps off)


def simulate(task: Task) -> dict:
    """Run ``task`` (in a worker process); returns the garment ``verts (T, V, 3)`` and the run's stats."""
    from accuracy import knee_height, perturb_joint

    from _common import plan_case

    from loosefit.sim import SimParams, simulate_sequence
    from loosefit.sim.plan import load_plan
    from loosefit.simulate import perturb_start

    body, garment, motion = plan_case(load_plan(task.plan), task.garment, task.motion, task.frames)
    params = SimParams.from_dict(task.params)
    if task.noise_seed is not None:
        garment = perturb_start(garment, task.noise_seed, task.sigma)
    if task.nudge_degrees:
        d = task.nudge_degrees
        motion = perturb_joint(motion, body.joint_names.index(NUDGE_JOINT), (d, d), seed=0)
    if task.quality is not None:
        params = dataclasses.replace(params, quality=task.quality, adaptive_quality=False)
    result = simulate_sequence(garment, body, motion, params)
    return {"verts": result.verts, "status": result.status, "reason": result.reason, "stats": result.stats,
            "below_knees": garment.verts[:, 2] < knee_height(body), "fps": motion.fps, "pid": os.getpid(),
            "faces": garment.faces, "body_verts": result.body_verts, "body_faces": body.faces}


def difference(a: np.ndarray, b: np.ndarray, below: np.ndarray, fps: float, samples: slice | None = None) -> dict:
    """How far ``a`` is from ``b`` ``(T, V, 3)``: RMSE (mm) overall, per half second and below the knees; with
    ``samples`` (frames ``offset::stride``), also over those frames alone and at each of them."""
    sq = ((a.astype(np.float64) - b) ** 2).sum(-1)  # (T, V)
    half = max(1, int(round(fps / 2)))
    at = {} if samples is None or not len(sq[samples]) else {
        "rmse_at_samples_mm": float(np.sqrt(sq[samples].mean()) * 1e3),
        "rmse_per_sample_mm": [float(np.sqrt(f.mean()) * 1e3) for f in sq[samples]]}
    return {**at,
        "rmse_mm": float(np.sqrt(sq.mean()) * 1e3),
        "rmse_per_half_second_mm": [float(np.sqrt(sq[i:i + half].mean()) * 1e3) for i in range(0, len(sq), half)],
        "rmse_below_knees_mm": float(np.sqrt(sq[:, below].mean()) * 1e3) if below.any() else None,
        "max_mm": float(np.sqrt(sq.max()) * 1e3),
    }


def probe_tasks(base: Task, probes: list[str], seeds: list[int], sigma: float, degrees: list[float]) -> dict:
    """The perturbed tasks of ``base`` by probe name (``steps`` is added once the base's steps are known)."""
    tasks = {}
    if "noise" in probes:
        tasks.update({f"noise-{s}": dataclasses.replace(base, noise_seed=s, sigma=sigma) for s in seeds})
    if "nudge" in probes:
        tasks.update({f"nudge-{d:g}": dataclasses.replace(base, nudge_degrees=d) for d in degrees})
    if "repeat" in probes:
        tasks["repeat"] = base
    return tasks


def mean_steps_futures(pool, base: Task, n: int, count: int, sigma: float) -> dict:
    """The mean-steps probe's runs: ``ref-k`` at ``n`` steps a frame and ``ref2n-k`` at ``2n``, noise seeds 1..count."""
    out = {}
    for k in range(1, count + 1):
        for name, quality in ((f"ref-{k}", n), (f"ref2n-{k}", 2 * n)):
            out[name] = pool.submit(simulate, dataclasses.replace(base, noise_seed=k, sigma=sigma, quality=quality))
    return out


def mean_steps(base: dict, runs: dict, count: int) -> dict:
    """The mean-steps figures (mm) from the base, its ``steps`` run and the ``ref-k`` / ``ref2n-k`` runs: the RMS
    distance between the mean at N and the mean at 2N steps (overall and below the knees) and each set's floor;
    empty when a run of either set crashed or failed."""
    from loosefit.metrics.reference import floor_m, mean_run, rmse_m

    sets = {"n": [base] + [runs.get(f"ref-{k}", {"error": "missing"}) for k in range(1, count + 1)],
            "2n": [runs.get("steps", {"error": "missing"})]
                  + [runs.get(f"ref2n-{k}", {"error": "missing"}) for k in range(1, count + 1)]}
    if any("error" in r or r["status"] != "ok" for rs in sets.values() for r in rs):
        return {}
    stacks = {k: np.stack([r["verts"] for r in rs]) for k, rs in sets.items()}
    means = {k: mean_run(v) for k, v in stacks.items()}
    below = base["below_knees"]
    return {"mean_steps_mm": 1e3 * rmse_m(means["n"], means["2n"]),
            "mean_steps_below_knees_mm": 1e3 * rmse_m(means["n"][:, below], means["2n"][:, below]) if below.any() else None,
            "floor_mm": 1e3 * floor_m(stacks["n"], means["n"]), "floor_2n_mm": 1e3 * floor_m(stacks["2n"], means["2n"]),
            "steps_n": int(base["stats"]["quality"]), "runs_per_mean": count + 1}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plan", default="configs/datasets/bench.yaml", help="a dataset plan")
    parser.add_argument("--garments", default="skirt,dress", help="comma-separated garments of the plan")
    parser.add_argument("--motions", default="walk-1,spin-1,jump-1,kick-1", help="comma-separated motions of the plan")
    parser.add_argument("--seconds", type=float, default=4.0, help="simulate the first seconds of each motion")
    parser.add_argument("--probes", default=",".join(DEFAULT_PROBES), help=f"comma-separated, of {list(PROBES)}")
    parser.add_argument("--sigma", type=float, default=1e-5, help="start-state noise, metres")
    parser.add_argument("--noise-seeds", default="0,1", help="comma-separated noise seeds")
    parser.add_argument("--nudge-degrees", default="0.5", help="comma-separated arm nudge angles, degrees")
    parser.add_argument("--sim-params", default=None, help="a simulation-parameter set of the plan (default: its first)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override one simulation parameter (repeatable), e.g. --set compression=30")
    parser.add_argument("--data", default=None, help="a store simulated from the plan: compare the base with it")
    parser.add_argument("--workers", type=int, default=2, help="simulations at a time (one process each)")
    parser.add_argument("--name", default="chaos-bench", help="results name")
    parser.add_argument("--sample-stride", type=int, default=0,
                        help="also compare at frames offset::stride alone (a held plan's settled poses: 40)")
    parser.add_argument("--sample-offset", type=int, default=0, help="see --sample-stride (a held plan: 39)")
    parser.add_argument("--references", type=int, default=4,
                        help="the mean-steps probe: noisy runs (seeds 1..K) at N and at 2N steps a frame")
    parser.add_argument("--save", default=None, help="a folder for the base runs as mesh sequences (<garment>-<motion>.npz)")
    args = parser.parse_args()

    from loosefit.sim.plan import load_plan

    plan = load_plan(args.plan)
    garments, motions = args.garments.split(","), args.motions.split(",")
    for kind, names, known in (("garment", garments, plan.garments), ("motion", motions, plan.motions)):
        for name in names:
            if name not in known:
                raise InputError(f"{kind} {name!r} is not in the plan (it has {sorted(known)})", args.plan)
    probes = [p for p in args.probes.split(",") if p]
    if "mean-steps" in probes and args.references < 1:
        raise InputError(f"--references must be at least 1, got {args.references}")
    if unknown := sorted(set(probes) - set(PROBES)):
        raise InputError(f"unknown probes {unknown}; known: {list(PROBES)}")
    params_name = args.sim_params or next(iter(plan.sim_params))
    if params_name not in plan.sim_params:
        raise InputError(f"simulation-parameter set {params_name!r} is not in the plan "
                         f"(it has {sorted(plan.sim_params)})", args.plan)
    params = plan.sim_params[params_name].with_overrides(args.set)
    seeds = [int(s) for s in args.noise_seeds.split(",")]
    degrees = [float(d) for d in args.nudge_degrees.split(",")]
    if args.sample_stride < 0 or args.sample_offset < 0:
        raise InputError("--sample-stride and --sample-offset must be >= 0")
    samples = slice(args.sample_offset, None, args.sample_stride) if args.sample_stride else None
    fps = 30.0
    frames = max(2, int(round(args.seconds * fps)))
    start = time.perf_counter()
    load = os.getloadavg()

    bases = {(g, m): Task(args.plan, g, m, frames, params.to_dict()) for g in garments for m in motions}
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(args.workers, mp_context=context, max_tasks_per_child=1) as pool:
        base_futures = {k: pool.submit(simulate, t) for k, t in bases.items()}
        probe_futures = {k: {name: pool.submit(simulate, t) for name, t in
                             probe_tasks(bases[k], probes, seeds, args.sigma, degrees).items()} for k in bases}
        base_runs = {k: _outcome(f) for k, f in base_futures.items()}
        if "steps" in probes or "mean-steps" in probes:  # N is the base's own (adaptive) step count
            for k, run in base_runs.items():
                if "error" not in run:
                    n = run["stats"]["quality"]
                    probe_futures[k]["steps"] = pool.submit(simulate, dataclasses.replace(bases[k], quality=2 * n))
                    if "mean-steps" in probes:
                        probe_futures[k].update(mean_steps_futures(pool, bases[k], n, args.references, args.sigma))
        probe_runs = {k: {name: _outcome(f) for name, f in fs.items()} for k, fs in probe_futures.items()}

    figures, runs = {}, {}
    for (g, m), base in base_runs.items():
        key = f"{g}/{m}"
        runs[f"{key}/base"] = _run_summary(base)
        if "error" in base:
            continue
        if args.save is not None:
            _save(Path(args.save) / f"{g}-{m}.npz", base)
        for name, run in probe_runs[(g, m)].items():
            runs[f"{key}/{name}"] = _run_summary(run)
            if "error" in run:
                continue
            for measure, value in difference(run["verts"], base["verts"], base["below_knees"], base["fps"],
                                             samples).items():
                figures[f"{key}/{name}/{measure}"] = value
            if name == "repeat":
                figures[f"{key}/repeat/bit_identical"] = bool(np.array_equal(run["verts"], base["verts"]))
                figures[f"{key}/repeat/other_process"] = run["pid"] != base["pid"]
        if "mean-steps" in probes:
            figures.update({f"{key}/{k}": v for k, v in mean_steps(base, probe_runs[(g, m)], args.references).items()})
        if args.data is not None:
            figures.update({f"{key}/stored/{k}": v for k, v in _against_store(args.data, g, m, base).items()})
    results = {"plan": args.plan, "garments": garments, "motions": motions, "frames": frames,
               "sigma_m": args.sigma, "sim_params": params.to_dict(), "overrides": args.set,
               "load_average_at_start": load, "wall_s": time.perf_counter() - start,
               "figures": figures, "runs": runs}
    save_results(args.name, results)
    print_table(figures, garments, motions)
    for g in garments:
        for m in motions:
            if f"{g}/{m}/mean_steps_mm" in figures:
                f = {k: figures[f"{g}/{m}/{k}"] for k in ("mean_steps_mm", "floor_mm", "floor_2n_mm", "steps_n")}
                print(f"{g}/{m}: means at {f['steps_n']} and {2 * f['steps_n']} steps a frame differ by "
                      f"{f['mean_steps_mm']:.1f} mm; floor {f['floor_mm']:.1f} mm (N), {f['floor_2n_mm']:.1f} mm (2N)")


def _outcome(future) -> dict:
    """A finished run, or ``{"error": ...}`` when it raised: one crashed run must not lose the others."""
    try:
        return future.result()
    except Exception as e:  # noqa: BLE001 - reported in the results, the other runs go on
        return {"error": f"{type(e).__name__}: {e}"}


def _run_summary(run: dict) -> dict:
    if "error" in run:
        return {"status": "crashed", "reason": run["error"]}
    keys = ("quality", "ms_per_frame", "penetration", "penetration_depth", "max_strain", "strain_p99", "pinned_drift")
    return {"status": run["status"], "reason": run["reason"],
            **{k: run["stats"][k] for k in keys if k in run["stats"]}}


def _save(path: Path, run: dict) -> None:
    from loosefit.io.mesh_sequence import MeshSequence

    path.parent.mkdir(parents=True, exist_ok=True)
    extra = {"body_verts": run["body_verts"], "body_faces": np.asarray(run["body_faces"], np.int64)}
    MeshSequence(run["verts"], np.asarray(run["faces"], np.int64), run["fps"], extra).save(path)


def _against_store(path: str, garment: str, motion: str, base: dict) -> dict:
    from loosefit.data.store import DatasetStore

    store = DatasetStore.open(path)
    stored = next((q for q in map(store.sequence, store.sequence_names())
                   if q.garment.split("+")[0] == garment and q.motion == motion), None)
    if stored is None:
        raise InputError(f"no sequence of {garment} on {motion} in the store", path)
    verts = np.asarray(stored.verts[:len(base["verts"])])
    return difference(verts, base["verts"], base["below_knees"], base["fps"])


def print_table(figures: dict, garments: list[str], motions: list[str]) -> None:
    """One line per garment and motion: RMSE (mm) of each probe against the base."""
    probes = sorted({k.split("/")[2] for k in figures if k.endswith("/rmse_mm")})
    print(f"{'':>16}" + "".join(f"{p:>11}" for p in probes) + "  (RMSE mm)")
    for g in garments:
        for m in motions:
            cells = [figures.get(f"{g}/{m}/{p}/rmse_mm") for p in probes]
            print(f"{g + '/' + m:>16}" + "".join(f"{c:11.1f}" if c is not None else f"{'':>11}" for c in cells))


if __name__ == "__main__":
    main()
