"""The exact collision handling with and without its skinned fallback (``SKINNED_FALLBACK``,
:mod:`loosefit.models.collision.handling`) on motion files and, given a store, on its validation sequences.

Per run and motion file, for the raw garment, the handling without the fallback (``plain``) and with it: the share
of triangles stretched past 4 times their rest area or collapsed under 20 % of it (%, over frames and triangles:
tears and crumples need no simulation to be seen), the mean unsigned dihedral angle (degrees), the surface points
more than 5 mm inside the full body (mean and worst frame, %), the deepest point (mm) and the handling's time (ms a
frame, one thread). With ``--data``: the pooled RMSE (mm, against the simulation) of each over the store's
validation sequences, with the same two shares.

    .venv/bin/python benchmarks/experiments/skinned_fallback.py --run pretrained:dress --run pretrained:skirt \\
        --motion ../shared/mocap/cmu-cc/006_08.bvh [--data .data/real-dress-val.zarr] [--depths 0.04,0.07]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import save_results  # noqa: E402


def surface_shares(verts: np.ndarray, faces: np.ndarray, rest_area: np.ndarray) -> tuple[float, float]:
    """Shares (%) of ``(frame, triangle)`` pairs of ``verts (T, V, 3)`` over 4 times and under 20 % of
    ``rest_area (F,)``."""
    from loosefit.geometry.normals import face_cross

    area = np.linalg.norm(face_cross(verts, faces), axis=-1) / rest_area
    return float(100 * (area > 4).mean()), float(100 * (area < 0.2).mean())


def main() -> None:
    from loosefit.animate import Animator
    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.geometry.normals import face_cross
    from loosefit.metrics.collision import penetrations
    from loosefit.metrics.surface import dihedral_angles_deg, interior_edges
    from loosefit.models.collision import handle_motion_collisions, handling
    from loosefit.motion.io import load_motion

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", action="append", required=True)
    ap.add_argument("--motion", action="append", default=[], help="a motion file (BVH: --joint-map)")
    ap.add_argument("--joint-map", default="cc")
    ap.add_argument("--data", default=None, help="a store whose validation sequences the runs' garment wears")
    ap.add_argument("--split", default="val", help="the store's split to score (default val; test only to report)")
    ap.add_argument("--depths", default=None, help="the fallback's depths, metres (default: the handling's)")
    ap.add_argument("--smooth", type=int, default=None, help="its smoothing passes (default: the handling's)")
    ap.add_argument("--name", default="skinned-fallback")
    a = ap.parse_args()
    if a.depths:
        handling.SKINNED_FALLBACK = tuple(float(x) for x in a.depths.split(","))
    if a.smooth is not None:
        handling.FALLBACK_SMOOTH = a.smooth
    torch.set_num_threads(1)
    body = AnnyBody(AnnyShape.parse(None))
    motions = {Path(m).stem: load_motion(m, body, joint_map=a.joint_map if m.endswith(".bvh") else None)
               for m in a.motion}
    posed = {k: body.pose(m).verts for k, m in motions.items()}
    results = {"depths_m": list(handling.SKINNED_FALLBACK), "smooth": handling.FALLBACK_SMOOTH, "motions": [],
               "validation": []}
    for run in a.run:
        animator = Animator(run, checkpoint="best", threads=1, device="cpu")
        faces, rest = np.asarray(animator.faces), animator.rest_garment
        rest_area = np.linalg.norm(face_cross(rest[None], faces), axis=-1)[0]
        edge, pair = interior_edges(faces)
        for label, motion in motions.items():
            raw = animator.animate_batch([motion])[0]
            out, ms = {"none": raw}, {"none": 0.0}
            for name, kept in (("plain", None), ("fallback", rest)):
                t = time.perf_counter()
                out[name] = handle_motion_collisions(raw, faces, body, motion, "exact", rest=kept)
                ms[name] = 1e3 * (time.perf_counter() - t) / len(raw)
            for (name, verts), pen in zip(out.items(), penetrations([(v, faces) for v in out.values()],
                                                                     posed[label], body.faces)):
                stretched, collapsed = surface_shares(verts, faces, rest_area)
                row = {"run": run, "motion": label, "handling": name, "stretched_pct": stretched,
                       "collapsed_pct": collapsed,
                       "bend_deg": float(np.abs(dihedral_angles_deg(verts, faces, edge, pair)).mean()),
                       "surface_inside_pct_mean": float(pen.surface_percent.mean()),
                       "surface_inside_pct_worst": float(pen.surface_percent.max()),
                       "deepest_mm": float(1e3 * pen.deepest_m.max()), "ms_per_frame": ms[name]}
                results["motions"].append(row)
                print(row, flush=True)
        if a.data:
            results["validation"] += validation_rows(a.data, run, animator, body, faces, rest, rest_area, a.split)
    print(save_results(a.name, results))


def validation_rows(data: str, run: str, animator, body, faces, rest, rest_area, split: str = "val") -> list[dict]:
    """Pooled RMSE (mm) and the two shares over the store's sequences of ``split``, per handling."""
    from loosefit.data import DatasetStore
    from loosefit.models.collision import handle_motion_collisions

    sums: dict = {}
    with DatasetStore.open(data) as store:
        for name in store.sequence_names(split):
            seq = store.sequence(name)
            motion, gt = store.motion(seq.motion), np.asarray(seq.verts[:])
            raw = animator.animate(motion)
            for label, kept in (("none", False), ("plain", None), ("fallback", rest)):
                verts = raw if kept is False else handle_motion_collisions(raw, faces, body, motion, "exact", rest=kept)
                stretched, collapsed = surface_shares(verts, faces, rest_area)
                s = sums.setdefault(label, np.zeros(5))
                s += [((verts - gt) ** 2).sum(), gt.shape[0] * gt.shape[1], stretched * len(gt), collapsed * len(gt),
                      len(gt)]
    rows = [{"run": run, "split": split, "handling": label, "rmse_mm": float(1e3 * np.sqrt(s[0] / s[1])),
             "stretched_pct": float(s[2] / s[4]), "collapsed_pct": float(s[3] / s[4])} for label, s in sums.items()]
    for row in rows:
        print(row, flush=True)
    return rows


if __name__ == "__main__":
    main()
