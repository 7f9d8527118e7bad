"""The demo's training, seed by seed: how much of the held-out spin's error is the seed.

Trains the demo's methods (:data:`loosefit.demo.DEMO_TRAINING`, the settings ``make demo`` ships) on a demo store
with ``train.seed`` set to each of ``--seeds`` (every other setting unchanged), two runs at a time on one thread
each, and scores each run on the store's held-out spin as the demo does: RMSE against the simulation, against the
mean of its reference runs, and the floor (both None for a sequence without reference runs). Per method, also the
mean and standard deviation over the seeds, and the RMSE of the seeds' averaged prediction. ``--data`` may be
another store of the demo's garment (such as ``configs/datasets/memory.yaml``'s) and ``--sequence`` another of its
held-out sequences (by default the first); the same runs score each sequence in turn. ``--set`` changes a setting
of every run after the demo's (a variant of its training: ``--set train.lr=1e-3``), named by ``--tag``. Runs resume
(``--runs``: ``<method>-<tag>-seed<k>`` folders).

Run: .venv/bin/python benchmarks/experiments/demo_seeds.py --data demo_out/demo.zarr --runs RUNS [--methods virtualbones,jointnet]
         [--seeds 0,1,2] [--set KEY=VALUE ...] [--tag demo] [--sequence NAME] [--name demo-seeds]
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import multiprocessing
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts

from _common import save_results  # noqa: E402


def train(method: str, seed: int, data: str, garment: str, run: str, changes: tuple[str, ...] = ()) -> float:
    """Train (or resume) one run as the demo does, with ``train.seed=seed`` and ``changes`` after its settings;
    seconds taken."""
    from loosefit.demo import DEMO_TRAINING, _train

    seeded = [f"train.seed={seed}", *changes] if method != "body-lbs" else []  # the baseline has no weights
    return _train(method, Path(data), garment, Path(run), [*DEMO_TRAINING[method], *seeded])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, help="a demo store (demo_out/demo.zarr)")
    ap.add_argument("--runs", required=True, help="folder of the runs (<method>-seed<k>)")
    ap.add_argument("--methods", default="virtualbones,jointnet")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--set", action="append", default=[], help="a setting of every run (KEY=VALUE), after the demo's")
    ap.add_argument("--tag", default="demo", help="names the runs of this variant")
    ap.add_argument("--sequence", help="the held-out sequence scored (default: the store's first)")
    ap.add_argument("--name", default="demo-seeds")
    a = ap.parse_args()
    from loosefit.animate import Animator
    from loosefit.data import DatasetStore
    from loosefit.metrics.errors import rmse_mm
    from loosefit.metrics.reference import floor_m, mean_run

    store = DatasetStore.open(a.data)
    held_out = store.sequence_names(split="test")
    if a.sequence is not None and a.sequence not in held_out:
        raise SystemExit(f"{a.data}: no held-out sequence {a.sequence!r} (has {held_out})")
    seq = store.sequence(a.sequence or held_out[0])
    methods, seeds = a.methods.split(","), [int(s) for s in a.seeds.split(",")]
    runs = {(m, s): Path(a.runs) / f"{m}-{a.tag}-seed{s}" for m in methods for s in seeds}
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(2, mp_context=context) as pool:  # one thread each, as the demo trains
        jobs = {key: pool.submit(train, *key, a.data, seq.garment, str(run), tuple(a.set)) for key, run in runs.items()}
        seconds = {key: job.result() for key, job in jobs.items()}

    gt, motion = np.asarray(seq.verts[:]), store.motion(seq.motion)
    runs_and_refs = [gt, *store.references(seq.name)]
    mean = mean_run(runs_and_refs) if len(runs_and_refs) > 1 else None  # no reference runs: no mean, no floor
    results = {"data": str(Path(a.data).resolve()), "sequence": seq.name, "changes": a.set,
               "floor_mm": floor_m(runs_and_refs, mean) * 1e3 if mean is not None else None,
               "references": len(runs_and_refs) - 1, "methods": {}}
    for m in methods:
        predictions = {s: Animator(runs[m, s]).animate(motion) for s in seeds}
        rows = {str(s): {"rmse_mm": rmse_mm(p, gt),
                         "rmse_vs_mean_mm": rmse_mm(p, mean) if mean is not None else None,
                         "train_s_this_call": round(seconds[m, s], 1)} for s, p in predictions.items()}
        rmse = [r["rmse_mm"] for r in rows.values()]
        averaged = np.mean(list(predictions.values()), 0)
        results["methods"][m] = {"seeds": rows, "rmse_mean_mm": statistics.fmean(rmse),
                                 "rmse_std_mm": statistics.stdev(rmse) if len(rmse) > 1 else None,
                                 "rmse_min_mm": min(rmse), "rmse_max_mm": max(rmse),
                                 "averaged_prediction_rmse_mm": rmse_mm(averaged, gt)}
        print(m, {s: round(r["rmse_mm"], 1) for s, r in rows.items()}, flush=True)
    lbs = Path(a.runs) / "body-lbs"  # the baseline has no weights to seed
    train("body-lbs", 0, a.data, seq.garment, str(lbs))
    results["body_lbs_rmse_mm"] = rmse_mm(Animator(lbs).animate(motion), gt)
    for row in results["methods"].values():
        row["rmse_mean_vs_body_lbs"] = row["rmse_mean_mm"] / results["body_lbs_rmse_mm"]
    save_results(a.name, results)


if __name__ == "__main__":
    main()
