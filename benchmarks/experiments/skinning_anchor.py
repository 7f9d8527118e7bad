"""Which skinned garment is closest to the simulation: body-LBS (each vertex with its closest body vertex's
weights, the rest pose's version of FitGar Eq. 5's anchor ``I M_b``) or LBS with inpainted weights
(:func:`loosefit.geometry.weight_inpainting.inpainted_skinning_weights`: copied within ``--distances`` of the
body, harmonic elsewhere, so that a hem between the legs follows both). A probe for FitGar's coarse anchor:
its coarse generator must undo whatever the anchor gets wrong.

Per sequence of a split, every ``--stride``-th frame: mean per-vertex error (mm) against the simulation and
against its ``fitgar`` smoothing (FitGar's coarse target), and the share of vertices whose weights were copied.

Run: .venv/bin/python benchmarks/experiments/skinning_anchor.py --data STORE [--split test] [--distances 0.02,0.05]
(writes benchmarks/results/<--name>.json)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import save_results  # noqa: E402
from accuracy_graph import every_nth_frame  # noqa: E402

from loosefit.body import AnnyBody, AnnyShape  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.geometry.weight_inpainting import inpainted_skinning_weights  # noqa: E402
from loosefit.models.fitgar_data import Smoother  # noqa: E402
from loosefit.sim.attach import garment_weights, skin_garment  # noqa: E402


def mean_error_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    return float(1e3 * np.linalg.norm(pred - gt, axis=-1).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, type=Path)
    parser.add_argument("--split", default="test")
    parser.add_argument("--distances", default="0.02,0.05", help="inpainting's copy distances, metres")
    parser.add_argument("--stride", type=int, default=10)
    parser.add_argument("--offset", type=int, default=0, help="first frame (held-pose stores: the settled frames)")
    parser.add_argument("--name", default="skinning-anchor")
    args = parser.parse_args()
    store = DatasetStore.open(args.data)
    distances = [float(d) for d in args.distances.split(",")]
    rows, bodies = [], {}
    for name in store.sequence_names(split=args.split):
        seq = store.sequence(name)
        if seq.body not in bodies:
            bodies[seq.body] = AnnyBody(AnnyShape.from_array(store.body(seq.body)))
        body, garment = bodies[seq.body], store.garment(seq.garment)
        motion = every_nth_frame(store.motion(seq.motion), args.stride, args.offset)
        gt = np.asarray(seq.verts[args.offset::args.stride], np.float32)
        smooth = Smoother(garment.faces, len(garment.verts), garment.pinned)(gt)
        lbs = skin_garment(garment.verts, garment_weights(garment.verts, body), body, motion)
        row = {"sequence": name, "garment": seq.garment, "kind": seq.garment.split("-")[0], "frames": len(gt),
               "body_lbs_mm": mean_error_mm(lbs, gt), "body_lbs_vs_smooth_mm": mean_error_mm(lbs, smooth)}
        for d in distances:
            w, copied = inpainted_skinning_weights(garment.verts, garment.faces, body.rest_verts(),
                                                   body.skinning_weights(), d)
            pred = skin_garment(garment.verts, w.astype(np.float32), body, motion)
            row[f"inpainted_{d}"] = {"mm": mean_error_mm(pred, gt), "vs_smooth_mm": mean_error_mm(pred, smooth),
                                     "copied_fraction": float(copied.mean())}
        rows.append(row)
        print(name, {k: v for k, v in row.items() if k.endswith("_mm") or k.startswith("inpainted")}, flush=True)
    summary = {}
    for kind in sorted({r["kind"] for r in rows}) + ["all"]:
        sel = [r for r in rows if kind in ("all", r["kind"])]
        summary[kind] = {"sequences": len(sel), "body_lbs_mm": float(np.mean([r["body_lbs_mm"] for r in sel])),
                         **{f"inpainted_{d}_mm": float(np.mean([r[f"inpainted_{d}"]["mm"] for r in sel]))
                            for d in distances}}
    save_results(args.name, {"data": str(args.data.resolve()), "split": args.split, "stride": args.stride,
                             "offset": args.offset, "distances_m": distances, "by_kind": summary, "rows": rows})


if __name__ == "__main__":
    main()
