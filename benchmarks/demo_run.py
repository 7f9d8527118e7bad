"""``make demo`` measured: its wall-clock time per stage and its held-out metrics, as JSON.

Runs :func:`loosefit.demo.run_demo` into a fresh folder (or ``--out``, which resumes what is there) and saves the
metrics of every held-out motion (the spin and the capture walk) per method (RMSE against the simulation, against the mean of its reference runs, the floor,
Hausdorff, collisions) and the seconds of every stage. Take the timing on an idle machine: the demo is meant to
finish in under 10 minutes on 2 cores.

Run: .venv/bin/python benchmarks/demo_run.py [--out DIR] [--name demo]   (writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import save_results  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", help="demo folder (default: a fresh temporary one)")
    ap.add_argument("--name", default="demo")
    a = ap.parse_args()
    from loosefit.demo import run_demo

    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(a.out or Path(tmp) / "demo_out")
        rows = run_demo(out)
        timings = json.loads((out / "timings.json").read_text())
    metrics = {}
    for motion, by_method in rows.items():
        lbs = by_method["body-lbs"]["rmse_mm"]
        metrics[motion] = {m: {k: v for k, v in r.items() if isinstance(v, (int, float)) or v is None}
                           for m, r in by_method.items()}
        for r in metrics[motion].values():
            r["rmse_vs_body_lbs"] = r["rmse_mm"] / lbs
    save_results(a.name, {"load_average_at_start": load, "load_average_at_end": os.getloadavg(), **timings,
                          "fresh": a.out is None, "held_out": metrics})  # {motion: {method: row}}


if __name__ == "__main__":
    main()
