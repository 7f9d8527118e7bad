"""Garment template generation time and vertex count per kind and edge length.

Run: .venv/bin/python benchmarks/garments.py   (writes benchmarks/results/garments.json)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

from loosefit.body import AnnyBody  # noqa: E402
from loosefit.garment import KINDS, make_garment  # noqa: E402


def main(edge_lengths=(0.04, 0.02, 0.01), seeds=(0, 1)) -> dict:
    body = AnnyBody()
    make_garment("skirt", body, seed=0)  # warm-up: body cross-sections, imports
    rows = []
    for h in edge_lengths:
        for kind in KINDS:
            times, verts = [], []
            for seed in seeds:
                t = time.perf_counter()
                g = make_garment(kind, body, seed=seed, edge_length=h)
                times.append(time.perf_counter() - t)
                verts.append(int(len(g.verts)))
            rows.append({"kind": kind, "edge_length_m": h, "seconds_mean": float(np.mean(times)), "vertices": verts})
            print(f"h={h:.3f} {kind:10s} {np.mean(times):6.2f} s  vertices {verts}", flush=True)
    return {"rows": rows}


if __name__ == "__main__":
    save_results("garments", main())
