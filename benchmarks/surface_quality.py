"""Surface quality of trained runs on a store's held-out sequences, against the simulation's own: how folded the
prediction is (the bend ratio), how far its folds are from the simulation's (roughness) and how many triangles
collapse, with the same numbers for the sequences' reference runs (perturbed simulations: the simulation's own
value, what an equally valid simulation scores).

Per sequence and run (the network's raw output, no collision handling; :mod:`loosefit.metrics.surface`):

- ``bend_ratio``: the prediction's mean unsigned dihedral angle over the simulation's (1: as folded as cloth;
  the target: at most 1.5);
- ``roughness_deg``: mean dihedral-angle difference from the simulation, degrees;
- ``collapsed_pct``: triangles under 20 % of their simulated area or flipped, percent;
- ``crumpled_pct``: triangles under 20 % of their rest area, percent (the simulation's own: nearly 0).

    .venv/bin/python benchmarks/surface_quality.py --data real.zarr --run virtualbones=RUNS/vb \\
        --run jointnet=pretrained:skirt/jointnet [--split test] [--name surface-quality-real]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.data import DatasetStore  # noqa: E402
from loosefit.metrics.surface import collapsed_pct, dihedral_pair_deg, roughness_from_dihedrals  # noqa: E402

#: A triangle under this fraction of its rest area has crumpled.
CRUMPLED_AREA = 0.2
TARGET_BEND_RATIO = 1.5


def areas(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Triangle areas ``(..., F)`` m^2 of ``verts (..., V, 3)``."""
    a, b, c = (verts[..., faces[:, k], :] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=-1)


def crumpled_pct(verts: np.ndarray, faces: np.ndarray, rest: np.ndarray) -> float:
    """Percent of the ``(frame, triangle)`` pairs of ``verts (T, V, 3)`` under :data:`CRUMPLED_AREA` of their rest area."""
    return float(100 * (areas(verts, faces) < CRUMPLED_AREA * areas(rest, faces)).mean())


def quality(pred: np.ndarray, gt: np.ndarray, faces: np.ndarray, rest: np.ndarray) -> dict:
    """The four numbers of the module doc for one prediction ``(T, V, 3)`` against ``gt``."""
    theta_pred, theta_gt = dihedral_pair_deg(pred, gt, faces)
    return {"bend_ratio": float(np.abs(theta_pred).sum() / np.abs(theta_gt).sum()),
            "roughness_deg": float(roughness_from_dihedrals(theta_pred, theta_gt).mean()),
            "collapsed_pct": collapsed_pct(pred, gt, faces), "crumpled_pct": crumpled_pct(pred, faces, rest)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, help="a dataset store with the held-out sequences")
    ap.add_argument("--run", action="append", required=True, help="NAME=RUN (a run folder or pretrained:NAME)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--name", default="surface-quality-real")
    a = ap.parse_args()
    store = DatasetStore.open(a.data)
    names = store.sequence_names(split=a.split)
    runs = dict(spec.split("=", 1) for spec in a.run)
    motions = [store.motion(store.sequence(n).motion) for n in names]
    predictions = {label: Animator(run, threads=2).animate_batch(motions) for label, run in runs.items()}
    rows = []
    for i, name in enumerate(names):
        seq = store.sequence(name)
        garment = store.garment(seq.garment)
        faces, rest = np.asarray(garment.faces), np.asarray(garment.verts, np.float64)
        gt = np.asarray(seq.verts[:], np.float64)
        refs = store.references(name)
        row = {"sequence": name, "frames": len(gt),
               "simulation": {"crumpled_pct": crumpled_pct(gt, faces, rest)},
               "references": None if refs is None or not len(refs) else
               {k: float(np.mean([quality(np.asarray(r, np.float64), gt, faces, rest)[k] for r in refs]))
                for k in ("bend_ratio", "roughness_deg", "collapsed_pct", "crumpled_pct")}}
        for label, preds in predictions.items():
            row[label] = quality(preds[i].astype(np.float64), gt, faces, rest)
        rows.append(row)
        print(name, " ".join(f"{label}: bend {row[label]['bend_ratio']:.2f} rough {row[label]['roughness_deg']:.1f} "
                             f"crumpled {row[label]['crumpled_pct']:.2f} %" for label in runs), flush=True)
    worst = {label: max(r[label]["bend_ratio"] for r in rows) for label in runs}
    save_results(a.name, {"data": a.data, "split": a.split, "runs": runs, "rows": rows,
                          "target_bend_ratio": TARGET_BEND_RATIO, "worst_bend_ratio": worst,
                          "pass": {label: w <= TARGET_BEND_RATIO for label, w in worst.items()}})


if __name__ == "__main__":
    main()
