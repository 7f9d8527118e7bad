"""Training levers side by side at equal CPU time: which ones help on held-out subjects of real capture?

For one garment of ``--data`` (a simulated store with ``val`` and ``test`` splits, e.g.
``configs/datasets/bench-real-small.yaml``; prepared here with ``--bones`` virtual bones), each ``--lever
NAME=OVERRIDE [OVERRIDE ...]`` trains ``--method`` (VirtualBones, or JointNet) with the CPU preset of
``benchmarks/accuracy.py`` (:data:`accuracy.CPU_TRAINING`) followed by the lever's overrides, into
``--runs/<NAME>/<garment>/<method>`` (for VirtualBones the folder ``learning_curve.py --runs RUNS/<NAME>`` shares as
its whole-set run). Every lever gets the same CPU
budget ``--budget-s``: a probe run of one epoch per stage (``--runs/<NAME>/probe``, validation included) measures
each stage's seconds per epoch, and the preset's epochs of both stages are scaled by one factor so that
``epochs_1 * s_1 + epochs_2 * s_2`` is the budget (:func:`scaled_epochs`; the probe's seconds are not
counted). A lever whose overrides differ from an earlier lever's only in the learning rate or its schedule
(``train.lr``, ``train.schedule``, ``train.min_lr``, ...) reuses that lever's probe.

The run validates on the store's ``val`` split and is animated from its best checkpoint by that validation; the
test split decides nothing: it is scored only with ``--score-test``, meant for once the levers are chosen (the same
command again: finished runs are found, the earlier rows kept and only the test sequences animated). Each run then
animates every training, validation and test sequence from frame 0, as at inference: RMSE (mm, pooled over frames
and vertices) per motion kind and split (the kinds of :func:`accuracy.errors_by_kind`), pooled per split and, for
training, over capture pieces and over procedural motions; on the test sequences also body-LBS's RMSE and, against
the mean of the reference runs, the model's RMSE beside the runs' floor (pooled, and per test motion).

JSON (``benchmarks/results/<name>.json``): ``levers/<NAME>/{overrides, epochs, probe, train_wall_s, cpu_s,
global_step, steps_per_s, stages, val_rmse_mm, train_rmse_mm, train_capture_rmse_mm, train_procedural_rmse_mm,
errors_by_kind, test}`` with ``test/{rmse_mm, lbs_rmse_mm, over_lbs, rmse_vs_mean_mm, floor_mm, vs_floor,
motions}``.

Run: .venv/bin/python benchmarks/experiments/levers.py --data DATA.zarr --runs RUNS --budget-s 300
         --lever baseline= --lever 'lr2e-3=train.lr=2e-3' [--garment skirt+average] [--name levers] [--score-test]
         [--mirror] [--method jointnet]
     (or --epochs LOW,HIGH instead of --budget-s: fixed epochs, no probe)
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import RESULTS, save_results  # noqa: E402
from accuracy import (CONFIGS, garments_with_test, held_out_sequences, kind_table, parse_sets,  # noqa: E402
                      pooled_rmse, train_run)

from loosefit.animate import Animator  # noqa: E402
from loosefit.config import load_config  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.metrics.reference import References, rmse_m  # noqa: E402
from loosefit.models.registry import run_config_class  # noqa: E402
from loosefit.rig.prepare import prepare  # noqa: E402
from loosefit.rig.virtual_bones import DEFAULT_BONES  # noqa: E402
from loosefit.train.validation import motion_kind  # noqa: E402

#: The trainer stages of each method the levers script trains.
STAGES = {"virtualbones": ("low", "high"), "jointnet": ("stage1", "stage2")}
#: Override keys that change no step's cost: a lever differing from another only in these reuses its probe.
COST_FREE = ("train.lr", "train.schedule", "train.min_lr", "train.step_epochs", "train.step_gamma", "train.seed")


def parse_lever(value: str) -> tuple[str, list[str]]:
    """``"NAME=key=value key=value"`` -> ``(NAME, [key=value, ...])``; ``"NAME="`` has no overrides."""
    name, sep, rest = value.partition("=")
    if not sep or not name or "/" in name:
        raise ValueError(f"--lever takes NAME=OVERRIDE [OVERRIDE ...] (NAME=: none), got {value!r}")
    overrides = rest.split()
    bad = [o for o in overrides if "=" not in o]
    if bad:
        raise ValueError(f"lever {name!r}: overrides are key=value, got {bad}")
    return name, overrides


def cost_key(overrides: list[str]) -> tuple[str, ...]:
    """The overrides that may change a step's cost (those not under :data:`COST_FREE`), in order."""
    return tuple(o for o in overrides if not o.partition("=")[0].startswith(COST_FREE))


def scaled_epochs(preset: dict[str, int], seconds: dict[str, float], budget_s: float) -> dict[str, int]:
    """The preset's epochs per stage times one factor, so that their estimated time ``sum(epochs * seconds)`` is
    ``budget_s`` (each stage at least one epoch). ``seconds``: measured seconds per epoch of each stage."""
    planned = sum(preset[s] * seconds[s] for s in preset)
    if planned <= 0:
        raise ValueError(f"the stages' seconds per epoch must be positive, got {seconds}")
    factor = budget_s / planned
    return {s: max(1, int(round(preset[s] * factor))) for s in preset}


def stage_rows(run: Path) -> dict[str, dict]:
    """Per stage, from the run's ``metrics.csv``: epochs, optimiser steps, seconds (validation included)."""
    out: dict[str, dict] = {}
    last_step = 0
    with open(run / "metrics.csv", newline="") as f:
        for row in csv.DictReader(f):
            entry = out.setdefault(row["stage"], {"epochs": 0, "steps": 0, "seconds": 0.0})
            step = int(row["step"])
            entry["epochs"] += 1
            entry["steps"] += step - last_step
            entry["seconds"] += float(row["seconds"])
            last_step = step
    for entry in out.values():
        entry["seconds_per_epoch"] = entry["seconds"] / max(entry["epochs"], 1)
        entry["steps_per_s"] = entry["steps"] / entry["seconds"] if entry["seconds"] > 0 else None
    return out


def score_splits(store: DatasetStore, animator, splits: dict[str, list[str]], lbs_mm: dict) -> dict:
    """Each sequence of ``splits`` (``{"train" | "val" | "test": names}``) animated once from frame 0: RMSE (mm)
    per motion kind and split (the keys of :func:`accuracy.errors_by_kind`), pooled per split, over the training
    capture pieces and procedural motions apart, and the test scores (body-LBS's RMSE per sequence in
    ``lbs_mm``; against the reference runs' mean beside their floor when the store has them)."""
    kinds: dict = {}
    pooled: dict[str, list] = {}
    base, lbs, mean, floor, motions = [], [], [], [], {}
    for split, names in splits.items():
        for name in names:
            seq = store.sequence(name)
            motion = store.motion(seq.motion)
            gt = np.asarray(seq.verts[:])
            pred = animator.animate(motion)
            n = gt.shape[0]
            sq = ((1000.0 * rmse_m(pred, gt)) ** 2, n)
            kinds.setdefault(motion_kind(motion.name, seq.motion), {}).setdefault(split, []).append(sq)
            pooled.setdefault(split, []).append(sq)
            if split == "train":
                pooled.setdefault("train_procedural" if ":seed=" in motion.name else "train_capture", []).append(sq)
            if split != "test":
                continue
            row = {"frames": n, "rmse_mm": float(np.sqrt(sq[0])), "lbs_rmse_mm": lbs_mm[name]}
            row["over_lbs"] = row["rmse_mm"] / row["lbs_rmse_mm"]
            base.append(sq)
            lbs.append((row["lbs_rmse_mm"] ** 2, n))
            refs = store.references(name)
            if len(refs):
                score = References(gt, refs).score(pred)
                row.update(rmse_vs_mean_mm=score.rmse_vs_mean_mm, floor_mm=score.floor_mm,
                           vs_floor=score.rmse_vs_mean_mm / score.floor_mm)
                mean.append((score.rmse_vs_mean_mm ** 2, n))
                floor.append((score.floor_mm ** 2, n))
            motions[seq.motion] = row
    test = {"rmse_mm": pooled_rmse(base), "lbs_rmse_mm": pooled_rmse(lbs), "motions": motions}
    if base:
        test["over_lbs"] = test["rmse_mm"] / test["lbs_rmse_mm"]
    if mean and len(mean) == len(base):
        test.update(rmse_vs_mean_mm=pooled_rmse(mean), floor_mm=pooled_rmse(floor))
        test["vs_floor"] = test["rmse_vs_mean_mm"] / test["floor_mm"]
    return {"errors_by_kind": kind_table(kinds), **{f"{k}_rmse_mm": pooled_rmse(v) for k, v in sorted(pooled.items())},
            "test": test}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="a simulated store with val and test splits")
    parser.add_argument("--runs", required=True, help="folder of the levers' run folders (resumed when present)")
    parser.add_argument("--garment", default=None, help="the garment (default: the store's one with test sequences)")
    parser.add_argument("--lever", action="append", required=True, help="NAME=OVERRIDE [OVERRIDE ...] (repeatable)")
    parser.add_argument("--budget-s", type=float, default=None, help="training seconds per lever (both stages)")
    parser.add_argument("--epochs", default=None, help="LOW,HIGH: these epochs for every lever instead of a budget "
                        "(a seed repeat of a lever at the epochs its budget gave)")
    parser.add_argument("--bones", type=int, default=DEFAULT_BONES, help="virtual bones per garment when preparing")
    parser.add_argument("--method", default="virtualbones", choices=sorted(STAGES), help="the network trained")
    parser.add_argument("--mirror", action="store_true", help="prepare the left-right mirror of every training "
                        "sequence too (its frames join the rig's solve), so that a lever may set data.mirror=true")
    parser.add_argument("--name", default="levers", help="results name: benchmarks/results/<name>.json")
    parser.add_argument("--score-test", action="store_true", help="score the test sequences too (once every lever "
                        "is chosen on validation; the rows of an earlier run of the same name are kept, not rescored)")
    args = parser.parse_args()
    if (args.budget_s is None) == (args.epochs is None):
        parser.error("give --budget-s or --epochs")
    method, stages = args.method, STAGES[args.method]
    fixed = None if args.epochs is None else dict(zip(stages, (int(e) for e in args.epochs.split(","))))
    try:
        levers = dict(parse_lever(v) for v in args.lever)
    except ValueError as e:
        parser.error(str(e))
    data, runs = Path(args.data), Path(args.runs)
    preset = parse_sets([], "cpu")[method]
    earlier = {}
    if args.score_test and (RESULTS / f"{args.name}.json").is_file():
        earlier = json.loads((RESULTS / f"{args.name}.json").read_text())["results"]["levers"]
    results: dict = {"data": str(data.resolve()), "runs": str(runs.resolve()), "preset": preset,
                     "budget_s": args.budget_s,
                     "prepare": prepare(data, bones=args.bones, mirror=args.mirror), "levers": {}}
    store = DatasetStore.open(data)
    garment = args.garment or garments_with_test(store)[0]
    results["garment"] = garment
    test = held_out_sequences(store, garment) if args.score_test else []
    lbs_run = runs / "body-lbs" / garment / "body-lbs"
    train_run("body-lbs", data, garment, lbs_run, [])
    lbs = Animator(lbs_run)
    lbs_mm = {}
    for name in test:
        seq = store.sequence(name)
        lbs_mm[name] = 1000.0 * rmse_m(lbs.animate(store.motion(seq.motion)), np.asarray(seq.verts[:]))
    validation = {"val_split": "val"}
    probes: dict[tuple, dict] = {}
    for lever, overrides in levers.items():
        sets = [*preset, *overrides]
        key = cost_key(overrides)
        if fixed is None and key not in probes:
            probe = runs / lever / "probe"
            print(f"== {lever}: probe one epoch per stage -> {probe}", flush=True)
            train_run(method, data, garment, probe,
                      [*sets, *(f"train.stages.{s}.epochs=1" for s in stages)], validation=validation)
            probes[key] = {"run": str(probe), "stages": stage_rows(probe)}
        if fixed is None:
            seconds = {s: probes[key]["stages"][s]["seconds_per_epoch"] for s in stages}
            train = load_config(run_config_class(method), CONFIGS / f"{method}.yaml", sets).train
            epochs = scaled_epochs({s: train.stage(s).epochs for s in stages}, seconds, args.budget_s)
        else:
            epochs = fixed
        run = runs / lever / garment / method
        print(f"== {lever}: {overrides} with epochs {epochs} -> {run}", flush=True)
        cpu = time.process_time()
        summary = train_run(method, data, garment, run,
                            [*sets, *(f"train.stages.{s}.epochs={e}" for s, e in epochs.items())], validation=validation)
        row = {"overrides": overrides, "epochs": epochs, "probe": probes.get(key), "cpu_s": time.process_time() - cpu,
               "train_wall_s": summary.get("train_wall_s"), "global_step": summary.get("global_step"),
               "checkpoint": summary["checkpoint"], "stages": stage_rows(run)}
        if row["train_wall_s"] and row["global_step"]:
            row["steps_per_s"] = row["global_step"] / row["train_wall_s"]
        animator = Animator(run)
        splits = {"train": animator.meta["train_sequences"], "val": animator.meta["val_sequences"], "test": test}
        before = earlier.get(lever, {})
        if before.get("overrides") == overrides and before.get("epochs") == epochs and "val_rmse_mm" in before:
            scored = score_splits(store, animator, {"test": test}, lbs_mm)
            row = {**before, "test": scored["test"], "test_rmse_mm": scored.get("test_rmse_mm")}
            for kind, e in scored["errors_by_kind"].items():
                row["errors_by_kind"].setdefault(kind, {}).update(e)
        else:
            row.update(score_splits(store, animator, splits, lbs_mm))
        results["levers"][lever] = row
        t = row["test"]
        print(f"   {lever}: {row.get('steps_per_s', float('nan')):.2f} steps/s, train {row['train_rmse_mm']:.1f} mm "
              f"(capture {row.get('train_capture_rmse_mm') or float('nan'):.1f}, "
              f"procedural {row.get('train_procedural_rmse_mm') or float('nan'):.1f}), val {row['val_rmse_mm']:.1f}"
              + (f", test {t['rmse_mm']:.1f} ({t['over_lbs']:.2f}x body-LBS" if t.get("rmse_mm") else "")
              + (f", vs mean {t['rmse_vs_mean_mm']:.1f} = {t['vs_floor']:.2f}x floor)" if "vs_floor" in t else
                 ")" if t.get("rmse_mm") else ""), flush=True)
        save_results(args.name, results)


if __name__ == "__main__":
    main()
