"""Ship trained runs as pretrained garments (``loosefit.pretrained``): each run reduced to what animation reads,
with what it was trained on and its test scores from an ``accuracy.py`` JSON.

Run: .venv/bin/python scripts/ship_pretrained.py --accuracy benchmarks/results/accuracy-real-skirt.json \\
         --runs RUNS --garment skirt+average --name skirt [--methods virtualbones jointnet]
(writes src/loosefit/pretrained/<name>-<method>/)
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from loosefit.pretrained import ROOT, ship


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
        print(f"{out}: {info['test']['rmse_mm']:.1f} mm RMSE on the test split "
              f"(body-LBS {info['test']['body_lbs_rmse_mm']:.1f})")


if __name__ == "__main__":
    main()
