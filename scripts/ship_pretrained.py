"""Ship trained runs as pretrained garments (``loosefit.pretrained``): each run reduced to what animation reads,
with what it was trained on and its test scores from an ``accuracy.py`` JSON.

Run: .venv/bin/python scripts/ship_pretrained.py --accuracy benchmarks/results/accuracy-real-skirt.json \\
         --runs RUNS --garment skirt+average --name skirt [--methods virtualbones jointnet]
(writes src/loosefit/pretrained/<name>-<method>/)

Each shipped garment is checked against its run on the test sequences of the JSON's store (when the store is here):
the largest vertex distance between the two animations and both RMSEs against the simulation, kept in its
``pretrained.json`` under ``storage_check``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from loosefit.pretrained import ROOT, ship


def storage_check(run: Path, shipped: Path, data: Path, sequences: list[str]) -> dict:
    """How far the shipped checkpoint (float16 or int8) moves the animation of ``sequences`` from the run's
    float32 one: the largest vertex distance (mm) and the pooled RMSE of each against the simulation (mm)."""
    from loosefit.animate import Animator
    from loosefit.data import DatasetStore

    store = DatasetStore.open(data)
    motions = [store.motion(store.sequence(name).motion) for name in sequences]
    gt = [np.asarray(store.sequence(name).verts[:], np.float64) for name in sequences]
    run_pred, shipped_pred = (Animator(folder, threads=2).animate_batch(motions) for folder in (run, shipped))
    rmse = [1000 * np.sqrt(np.mean(np.concatenate([np.sum((p - g) ** 2, -1).ravel() for p, g in zip(preds, gt)])))
            for preds in (run_pred, shipped_pred)]
    largest = max(float(np.abs(np.linalg.norm(a - b, axis=-1)).max()) for a, b in zip(run_pred, shipped_pred))
    return {"sequences": len(sequences), "max_vertex_distance_mm": 1000 * largest,
            "run_rmse_mm": rmse[0], "shipped_rmse_mm": rmse[1]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--accuracy", required=True, help="the accuracy.py results JSON that trained and scored the runs")
    ap.add_argument("--runs", required=True, help="accuracy.py's --runs folder")
    ap.add_argument("--garment", required=True, help="the store's garment entry, e.g. skirt+average")
    ap.add_argument("--name", required=True, help="the shipped name: pretrained:<name>[/<method>]")
    ap.add_argument("--methods", nargs="+", default=["virtualbones", "jointnet"])
    a = ap.parse_args()
    results = json.loads(Path(a.accuracy).read_text())["results"]
    garment = results["garments"][a.garment]
    for method in a.methods:
        overall = garment["metrics"][method]["overall"]
        info = {
            "trained_on": {"data": results["data"], "garment": a.garment, "sequences": garment["sequences"]["train"],
                           "validated_on": garment["sequences"]["val"], "preset": results["preset"],
                           "overrides": results["overrides"][method]},
            "test": {"sequences": garment["sequences"]["test"],
                     **{k: overall.get(k) for k in ("rmse_mm", "rmse_vs_mean_mm", "rmse_vs_mean_corrected_mm",
                                                    "floor_mm", "collision_pct")},
                     "body_lbs_rmse_mm": garment["metrics"]["body-lbs"]["overall"]["rmse_mm"]},
            "results": Path(a.accuracy).name,
        }
        out = ship(Path(a.runs) / a.garment / method, ROOT / f"{a.name}-{method}", info)
        if Path(results["data"]).is_dir():
            meta = json.loads((out / "pretrained.json").read_text())
            meta["storage_check"] = storage_check(Path(a.runs) / a.garment / method, out, Path(results["data"]),
                                                  garment["sequences"]["test"])
            (out / "pretrained.json").write_text(json.dumps(meta, indent=1))
            print(f"{out}: int8 {meta['int8'] or 'nothing'}, float16 the rest; it moves the test animations by at most "
                  f"{meta['storage_check']['max_vertex_distance_mm']:.2f} mm")
        print(f"{out}: {info['test']['rmse_mm']:.1f} mm RMSE on the test split "
              f"(body-LBS {info['test']['body_lbs_rmse_mm']:.1f})")


if __name__ == "__main__":
    main()
