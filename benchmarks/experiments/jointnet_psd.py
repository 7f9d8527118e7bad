"""What JointNet's pose-space deformation adds on held-out motions, and what its smooth part keeps.

Animates a trained JointNet run (a free PSD basis, as the paper) on a store's sequences three ways: as trained,
without the PSD (``psd=False``: the skinned bones alone) and with its basis projected onto the garment's ``k``
smoothest vibration modes (:func:`loosefit.models.jointnet.project_psd`) for each ``--modes``; prints per way the
pooled RMSE (mm), the bend ratio (the prediction's mean unsigned dihedral angle over the simulation's), the
roughness (degrees) and the crumpled share (triangles under 20 % of their rest area, %).

Run: .venv/bin/python benchmarks/experiments/jointnet_psd.py --data real.zarr --run RUNS/jointnet
         [--split val] [--every 3] [--modes 16,64,256,512]
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from surface_quality import quality  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.data import DatasetStore  # noqa: E402
from loosefit.models.jointnet import project_psd  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--run", required=True, help="a JointNet run trained with a free PSD basis")
    ap.add_argument("--split", default="val", help="the sequences animated (choose settings on validation)")
    ap.add_argument("--every", type=int, default=3, help="every n-th sequence of the split")
    ap.add_argument("--modes", default="16,64,256,512")
    a = ap.parse_args()
    store = DatasetStore.open(a.data)
    names = store.sequence_names(split=a.split)[::a.every]
    motions = [store.motion(store.sequence(n).motion) for n in names]
    gts = [np.asarray(store.sequence(n).verts[:], np.float64) for n in names]
    garment = store.garment(store.sequence(names[0]).garment)
    faces, rest = np.asarray(garment.faces), np.asarray(garment.verts, np.float64)
    animator = Animator(a.run, threads=2)
    trained = animator.model

    def report(label: str) -> None:
        preds = [p.astype(np.float64) for p in animator.animate_batch(motions)]
        squares = np.concatenate([np.sum((p - g) ** 2, -1).ravel() for p, g in zip(preds, gts)])
        q = [quality(p, g, faces, rest) for p, g in zip(preds, gts)]
        print(f"{label:12s} RMSE {1000 * np.sqrt(squares.mean()):.2f} mm, bend ratio "
              f"{np.mean([x['bend_ratio'] for x in q]):.2f} (max {max(x['bend_ratio'] for x in q):.2f}), roughness "
              f"{np.mean([x['roughness_deg'] for x in q]):.1f} deg, crumpled {np.mean([x['crumpled_pct'] for x in q]):.2f} %",
              flush=True)

    report("free PSD")
    for k in (int(m) for m in a.modes.split(",") if m):
        animator.model = project_psd(trained, k)
        report(f"{k} modes")
    animator.model = trained
    forward = trained.forward
    trained.forward = functools.partial(forward, psd=False)
    report("no PSD")
    trained.forward = forward


if __name__ == "__main__":
    main()
