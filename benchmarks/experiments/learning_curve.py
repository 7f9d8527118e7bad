"""VirtualBones' held-out error against the share of training motions: is more data the next step?

For each garment of ``--data`` (a simulated, prepared store with test sequences, e.g.
``configs/datasets/bench-large.yaml``) and each share in ``--fractions`` (default 0.25, 0.5, 1), VirtualBones
trains on that share of the training motions of every kind (:func:`loosefit.train.validation.keep_fraction`:
nested shares, ranked by name, every kind kept), with the same carved validation motions at every share
(``--val-fraction`` of the training motions, or the store's ``val`` split) and the CPU preset of
``benchmarks/accuracy.py`` (``--set`` overrides after it). The share 1 run is ``--runs/<garment>/virtualbones``,
the folder ``accuracy.py`` trains, so the two benchmarks share it; the others are ``virtualbones-f<share>``.
Every held-out sequence is animated and scored against its simulation, against the mean of its reference
runs and beside their floor (:mod:`loosefit.metrics.reference`); body-LBS is the same at every share.

JSON (``benchmarks/results/<name>.json``): ``curve/<garment>/<share>/{train_motions, train_frames, rmse_mm,
rmse_vs_mean_mm, over_lbs, train_wall_s}`` pooled over the held-out sequences (RMSE over all their frames
and vertices), and per held-out motion ``.../motions/<motion>/{rmse_mm, rmse_vs_mean_mm, floor_mm,
vs_floor}`` (``vs_floor``: ``rmse_vs_mean_mm / floor_mm``, the target being at most 2).

Run: .venv/bin/python benchmarks/experiments/learning_curve.py --data DATA.zarr --runs RUNS [--garments skirt+average]
         [--fractions 0.25,0.5,1] [--set virtualbones:train.stages.low.epochs=30] [--name learning-curve]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import save_results  # noqa: E402
from accuracy import garment_validation, garments_with_test, held_out_sequences, parse_sets, train_run  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.metrics.reference import References, rmse_m  # noqa: E402
from loosefit.rig.prepare import prepare  # noqa: E402
from loosefit.rig.virtual_bones import DEFAULT_BONES  # noqa: E402


def run_folder(runs: Path, garment: str, fraction: float) -> Path:
    """Where the share ``fraction`` trains: ``accuracy.py``'s own VirtualBones run for the whole set."""
    return runs / garment / ("virtualbones" if fraction == 1 else f"virtualbones-f{fraction:g}")


def pooled_mm(squares: list[tuple[float, int]]) -> float:
    """RMSE (mm) over several sequences from their ``(mean square m^2, count)``."""
    total = sum(n for _, n in squares)
    return 1000.0 * float(np.sqrt(sum(ms * n for ms, n in squares) / total))


def score_share(store: DatasetStore, garment: str, animator, lbs, names: list[str]) -> dict:
    """Pooled and per-motion scores of one share's model (and body-LBS) on the held-out ``names``."""
    motions, base_sq, mean_sq, lbs_sq = {}, [], [], []
    for name in names:
        seq = store.sequence(name)
        motion = store.motion(seq.motion)
        gt = np.asarray(seq.verts[:])
        pred = animator.animate(motion)
        count = gt.shape[0] * gt.shape[1]
        base = rmse_m(pred, gt)
        base_sq.append((base**2, count))
        lbs_sq.append((rmse_m(lbs.animate(motion), gt) ** 2, count))
        motions[seq.motion] = {"rmse_mm": 1000.0 * base}
        refs = store.references(name)
        if len(refs):
            score = References(gt, refs).score(pred)
            motions[seq.motion].update(rmse_vs_mean_mm=score.rmse_vs_mean_mm, floor_mm=score.floor_mm,
                                       vs_floor=score.rmse_vs_mean_mm / score.floor_mm)
            mean_sq.append(((score.rmse_vs_mean_mm / 1000.0) ** 2, count))
    out = {"rmse_mm": pooled_mm(base_sq), "lbs_rmse_mm": pooled_mm(lbs_sq), "motions": motions}
    out["over_lbs"] = out["rmse_mm"] / out["lbs_rmse_mm"]
    if len(mean_sq) == len(names):
        out["rmse_vs_mean_mm"] = pooled_mm(mean_sq)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="a simulated dataset with test sequences")
    parser.add_argument("--runs", required=True, help="folder of the run folders (accuracy.py's, shared)")
    parser.add_argument("--garments", default=None, help="comma-separated garment names (default: all with test sequences)")
    parser.add_argument("--fractions", default="0.25,0.5,1", help="shares of the training motions, in (0, 1]")
    parser.add_argument("--set", action="append", default=[], help="virtualbones:section.key=value (repeatable)")
    parser.add_argument("--bones", type=int, default=DEFAULT_BONES, help="virtual bones per garment when preparing")
    parser.add_argument("--val-fraction", type=float, default=0.2, help="share of the training motions that validate")
    parser.add_argument("--name", default="learning-curve", help="results name: benchmarks/results/<name>.json")
    args = parser.parse_args()
    fractions = sorted(float(f) for f in args.fractions.split(","))
    if not fractions or not all(0 < f <= 1 for f in fractions):
        parser.error("--fractions takes shares in (0, 1], e.g. 0.25,0.5,1")
    sets = parse_sets(args.set, "cpu")["virtualbones"]
    data, runs = Path(args.data), Path(args.runs)
    results: dict = {"data": str(data.resolve()), "runs": str(runs.resolve()), "overrides": sets, "fractions": fractions,
                     "prepare": prepare(data, bones=args.bones), "curve": {}}
    store = DatasetStore.open(data)
    for garment in args.garments.split(",") if args.garments else garments_with_test(store):
        names = held_out_sequences(store, garment)
        lbs_run = runs / garment / "body-lbs"
        train_run("body-lbs", data, garment, lbs_run, [])
        lbs = Animator(lbs_run)
        validation = garment_validation(store, garment, args.val_fraction)
        for fraction in fractions:
            run = run_folder(runs, garment, fraction)
            start = time.perf_counter()
            print(f"== {garment}: VirtualBones on {fraction:g} of the training motions -> {run}", flush=True)
            summary = train_run("virtualbones", data, garment, run, sets,
                                validation={**validation, **({"train_fraction": fraction} if fraction < 1 else {})})
            animator = Animator(run)
            trained = animator.meta["train_sequences"]
            row = {"train_motions": len({store.sequence(n).motion for n in trained}),
                   "train_frames": int(sum(store.sequence(n).verts.shape[0] for n in trained)),
                   "train_wall_s": summary.get("train_wall_s"), "call_s": time.perf_counter() - start,
                   **score_share(store, garment, animator, lbs, names)}
            results["curve"].setdefault(garment, {})[f"{fraction:g}"] = row
            print(f"   {row['train_motions']} motions, {row['train_frames']} frames: held-out RMSE "
                  f"{row['rmse_mm']:.1f} mm ({row['over_lbs']:.2f}x body-LBS)"
                  + (f", against the mean {row['rmse_vs_mean_mm']:.1f}" if "rmse_vs_mean_mm" in row else ""), flush=True)
            save_results(args.name, results)


if __name__ == "__main__":
    main()
