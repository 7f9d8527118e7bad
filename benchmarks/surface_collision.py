"""The collision handling's surface pass (loosefit's addition beyond SwinGar Eq. 10): what it adds to a frame's time
and how much of the garment's surface between the vertices it takes out of the body.

Input: no trained model is needed. A skirt from the template (``loosefit garment make``'s, about 4k vertices by
default) is skinned to the body (the body-LBS baseline, :func:`~loosefit.sim.attach.body_lbs`) along each motion: on
kicks and runs a leg passes through it, at the vertices and between them. Each motion is corrected the way
``loosefit animate --collision exact`` does (:func:`~loosefit.models.collision.handle_motion_collisions`: the posed
proxy pushed to enclose the full body, inflated 2 mm, the cull, SwinGar Eq. 10), with the surface pass off
(``surface=False``, the paper's vertex-only handling) and on (the default).

Time: the per-frame correction (:func:`~loosefit.models.collision.correct_frame` over the motion, one torch thread,
the posed proxy's trees built beforehand, as both runs share them), the least of ``--repeats`` runs of each; "added"
is the difference. The process's CPU time is the figure (the machines are shared: the wall clock of the same run
varied 2-3x here), the wall clock is saved beside it. Field points: how many points a frame the exact field was asked
about (vertices, Eq. 10's neighbours, surface samples).

Measures, against the posed full-resolution body (what a viewer sees), per frame then averaged / worst:

- ``surface``: edge midpoints and triangle centroids (:func:`~loosefit.metrics.collision.surface_samples`, the points
  the pass checks) more than 5 mm inside, in percent, and the deepest of them (mm);
- ``between``: points the pass never checks (on each triangle the three points of barycentric weights (2/3, 1/6, 1/6),
  on each edge its two quarter points): what is left between the samples;
- ``vertices``: the vertices more than 5 mm inside;
- ``untouched``: the vertices where nothing penetrated the handling's surface in the input (the vertex outside it, every
  sample of its triangles less than the pass's tolerance inside): how far they moved (the shape change where nothing
  penetrates; a vertex next to a moved one can still be moved by a later pass, and counts here).

Targets: at most 10 ms a frame added at 4k vertices on one CPU thread; surface
points more than 5 mm inside at most 0.5 % on average and 1.5 % in any frame; the deepest at most 15 mm.

    PYTHONPATH=src .venv/bin/python benchmarks/surface_collision.py [--edge 0.0165] [--motion kick:1:3 ...]

Motions: ``kind:seed:seconds`` (procedural) or a BVH file (``--joint-map cc`` for ``../shared/mocap``), the first
``--frames`` frames. Writes ``benchmarks/results/surface_collision.json`` (``--append``: one motion a run, the rows of
the others kept).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, save_results  # noqa: E402

#: ``../shared/mocap/cmu-cc`` of the checkout (or of a folder above a worktree), None where there is none.
MOCAP = next((up / "shared" / "mocap" / "cmu-cc" for up in Path(__file__).resolve().parents
              if (up / "shared" / "mocap" / "cmu-cc").is_dir()), None)
#: A kick, a run and a squat (procedural), and CMU's run / jog 002_03 and forward jumps 001_01 when the clips are here.
DEFAULT_MOTIONS = ["kick:1:3", "run:1:3", "squat:2:3"] + ([str(MOCAP / "002_03.bvh"), str(MOCAP / "001_01.bvh")]
                                                         if MOCAP is not None else [])
DEPTH = 0.005
TARGETS = {"added_ms": 10.0, "surface_percent_mean": 0.5, "surface_percent_worst": 1.5, "deepest_mm": 15.0}


def held_out_samples(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Points the surface pass never checks, ``(..., 3 F + 2 E, 3)``: per triangle the three of barycentric weights
    (2/3, 1/6, 1/6) and its rotations, per edge the two quarter points."""
    from loosefit.geometry.laplacian import edges

    v = np.asarray(verts, np.float64)
    f = np.asarray(faces, np.int64)
    e = edges(f)
    a, b, c = (v[..., f[:, k], :] for k in range(3))
    x, y = v[..., e[:, 0], :], v[..., e[:, 1], :]
    big, small = 2.0 / 3.0, 1.0 / 6.0
    return np.concatenate([big * a + small * (b + c), big * b + small * (a + c), big * c + small * (a + b),
                           0.75 * x + 0.25 * y, 0.25 * x + 0.75 * y], axis=-2)


def depth_per_frame(points: np.ndarray, bodies: list) -> np.ndarray:
    """``(T, N)`` metres inside the body (positive inside) of ``points (T, N, 3)``, frame ``t`` against ``bodies[t]``."""
    return np.stack([-body.query(p) for body, p in zip(bodies, points)])


def summary(depth: np.ndarray) -> dict:
    """Percent more than :data:`DEPTH` inside per frame (mean, worst) and the deepest point, mm."""
    share = 100.0 * (depth > DEPTH).mean(1)
    return {"percent_mean": float(share.mean()), "percent_worst": float(share.max()),
            "deepest_mm": float(1e3 * max(depth.max(), 0.0))}


def load_motions(specs: list[str], body, joint_map: str, frames: int) -> dict:
    from loosefit.motion.io import load_motion
    from loosefit.motion.procedural import generate

    motions = {}
    for spec in specs:
        parts = spec.split(":")
        if len(parts) == 3 and not Path(spec).exists():
            motion = generate(parts[0], float(parts[2]), int(parts[1]), body)
            label = f"{parts[0]}-seed{parts[1]}"
        else:
            motion = load_motion(spec, body, joint_map=joint_map if spec.endswith(".bvh") else None)
            label = Path(spec).stem
        motions[label] = motion.slice(0, min(frames, len(motion.rotations)))
    return motions


def correct(raw: np.ndarray, faces: np.ndarray, posed: np.ndarray, proxy_faces: np.ndarray, meshes: list,
            surface: bool, passes: int) -> tuple[np.ndarray, tuple[float, float], float]:
    """The exact handling's per-frame work on trees built beforehand: corrected ``(T, V, 3)``, (wall, CPU) seconds,
    field points a frame."""
    from loosefit.geometry.ray_cull import AxisRayCuller
    from loosefit.models.collision import CULL_CELL, CollisionResolver, ExactSDF, correct_frame

    asked = [0]

    class Counted(ExactSDF):
        def _query(self, points, *hint):
            asked[0] += len(points)
            return super()._query(points, *hint)

    resolver = CollisionResolver(faces, raw.shape[1], surface=surface, passes=passes)
    culler = AxisRayCuller(posed[0], proxy_faces, CULL_CELL)
    out = np.empty_like(raw)
    start, cpu = time.perf_counter(), time.process_time()
    for t in range(len(raw)):
        out[t] = correct_frame(raw[t], resolver, Counted(meshes[t]), None, culler.update(posed[t], raw[t]))[0]
    return out, (time.perf_counter() - start, time.process_time() - cpu), asked[0] / len(raw)


def main() -> None:
    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.garment.templates import make_garment
    from loosefit.geometry.signed_distance import BodySDF
    from loosefit.metrics.collision import surface_samples
    from loosefit.models.collision import (PROXY_INFLATE, SURFACE_PASSES, SURFACE_TOLERANCE, ExactSDF,
                                           handle_motion_collisions, inflated)
    from loosefit.sim.attach import body_lbs
    from loosefit.sim.collider import enclosing_frames

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--edge", type=float, default=0.0165, help="skirt edge length, m (0.0165: about 4k vertices)")
    ap.add_argument("--length", type=float, default=0.6, help="skirt length, m")
    ap.add_argument("--motion", action="append", default=None, help="kind:seed:seconds or a BVH file (repeatable)")
    ap.add_argument("--joint-map", default="cc")
    ap.add_argument("--frames", type=int, default=90, help="frames of each motion at most")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs of each handling (the least counts)")
    ap.add_argument("--passes", type=int, default=None, help="surface passes at most (default: the handling's)")
    ap.add_argument("--out", default="surface_collision")
    ap.add_argument("--append", action="store_true",
                    help="keep the other motions' rows of results/<out>.json (one motion a run; pooled over all)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    args.passes = SURFACE_PASSES if args.passes is None else args.passes

    body = AnnyBody(AnnyShape.parse(None))
    proxy = body.collision_proxy()
    garment = make_garment("skirt", body, seed=0, edge_length=args.edge, length=args.length, flare=12.0)
    faces = garment.faces
    V = len(garment.verts)
    motions = load_motions(args.motion or DEFAULT_MOTIONS, body, args.joint_map, args.frames)
    print(f"skirt: {V} vertices, {len(faces)} triangles; surface pass: {args.passes} passes, tolerance "
          f"{SURFACE_TOLERANCE * 1e3:g} mm", flush=True)
    rows = []
    saved = RESULTS / f"{args.out}.json"
    if args.append and saved.is_file():
        before = json.loads(saved.read_text())["results"]
        if before["garment"]["vertices"] != V or before["surface_passes"] != args.passes:
            raise SystemExit(f"{saved} was measured on another skirt or pass count: drop --append")
        rows = [r for r in before["rows"] if r["motion"] not in motions]
    for label, motion in motions.items():
        raw = body_lbs(garment.verts, body, motion)
        T = len(raw)
        # the handling's surface, as handle_motion_collisions makes it, and each frame's tree (shared by both runs)
        posed = inflated(enclosing_frames(body, motion, within=raw), proxy.faces, PROXY_INFLATE)
        meshes = [BodySDF(posed[t], proxy.faces) for t in range(T)]
        results, seconds, cpu, asked = {}, {}, {}, {}
        for surface in (False, True):
            seconds[surface] = cpu[surface] = np.inf
            for _ in range(max(args.repeats, 1)):
                out, (wall, used), points = correct(raw, faces, posed, proxy.faces, meshes, surface, args.passes)
                seconds[surface], cpu[surface] = min(seconds[surface], wall), min(cpu[surface], used)
            results[surface], asked[surface] = out, points
        # what loosefit animate runs gives the same (its own trees and cull window)
        same_as_cli = None
        if args.passes == SURFACE_PASSES:
            cli = handle_motion_collisions(raw, faces, body, motion, "exact")
            same_as_cli = float(np.abs(cli - results[True]).max())
        full = [BodySDF(v, body.faces) for v in body.pose(motion).verts]
        # where nothing penetrated the handling's surface in the input: the vertex outside it, no edge midpoint or
        # centroid of its triangles more than the tolerance inside
        def field(points: np.ndarray) -> np.ndarray:
            return np.stack([ExactSDF(m)(torch.from_numpy(np.asarray(p, np.float64))).numpy()
                             for m, p in zip(meshes, points)])

        a, b, c = (raw[:, faces[:, k]].astype(np.float64) for k in range(3))
        per_triangle = np.concatenate([(a + b) / 2, (b + c) / 2, (c + a) / 2, (a + b + c) / 3], axis=1)
        deep_triangle = (field(per_triangle) < -SURFACE_TOLERANCE).reshape(T, 4, -1).any(1)  # (T, F)
        near = np.zeros((V, T), bool)
        for k in range(3):
            np.logical_or.at(near, faces[:, k], deep_triangle.T)
        untouched = ~near.T & (field(raw) >= 0)
        row = {"motion": label, "frames": T, "vertices": V, "triangles": int(len(faces))}
        for name, verts in (("input", raw), ("vertex_only", results[False]), ("surface", results[True])):
            moved = np.linalg.norm(verts - raw, axis=-1)
            row[name] = {
                "surface": summary(depth_per_frame(surface_samples(verts, faces), full)),
                "between": summary(depth_per_frame(held_out_samples(verts, faces), full)),
                "vertices": summary(depth_per_frame(verts, full)),
                "moved_percent": float(100.0 * (moved > 0).mean()),
                "moved_mm_max": float(1e3 * moved.max()),
                "untouched_moved_mm_max": float(1e3 * moved[untouched].max()) if untouched.any() else 0.0,
                "untouched_moved_count": int((moved[untouched] > 0).sum()),
            }
        row["untouched_percent"] = float(100.0 * untouched.mean())
        # CPU time of the process (one thread): what the machine's other work does not inflate as much as the wall
        row["ms_per_frame"] = {"vertex_only": 1e3 * cpu[False] / T, "surface": 1e3 * cpu[True] / T,
                               "added": 1e3 * (cpu[True] - cpu[False]) / T}
        row["wall_ms_per_frame"] = {"vertex_only": 1e3 * seconds[False] / T, "surface": 1e3 * seconds[True] / T,
                                    "added": 1e3 * (seconds[True] - seconds[False]) / T}
        row["field_points_per_frame"] = {"vertex_only": asked[False], "surface": asked[True]}
        row["same_as_handle_motion_collisions_max_m"] = same_as_cli
        rows.append(row)
        s, i, o = row["surface"], row["input"], row["vertex_only"]
        print(f"{label:14s} {T:3d} frames: surface points >5 mm inside {i['surface']['percent_mean']:.2f} % "
              f"(worst {i['surface']['percent_worst']:.2f} %, deepest {i['surface']['deepest_mm']:.0f} mm) -> vertex "
              f"pass {o['surface']['percent_mean']:.2f} % ({o['surface']['percent_worst']:.2f} %, "
              f"{o['surface']['deepest_mm']:.0f} mm) -> surface pass {s['surface']['percent_mean']:.2f} % "
              f"({s['surface']['percent_worst']:.2f} %, {s['surface']['deepest_mm']:.0f} mm); between samples "
              f"{o['between']['percent_mean']:.2f} % ({o['between']['deepest_mm']:.0f} mm) -> "
              f"{s['between']['percent_mean']:.2f} % ({s['between']['deepest_mm']:.0f} mm); vertices "
              f"{s['vertices']['percent_mean']:.2f} % ({s['vertices']['deepest_mm']:.0f} mm); untouched moved "
              f"{s['untouched_moved_count']} (max {s['untouched_moved_mm_max']:.1f} mm); "
              f"{row['ms_per_frame']['vertex_only']:.1f} -> {row['ms_per_frame']['surface']:.1f} ms/frame "
              f"(+{row['ms_per_frame']['added']:.1f}; wall +{row['wall_ms_per_frame']['added']:.1f}), field points "
              f"{asked[False]:.0f} -> {asked[True]:.0f}",
              flush=True)
    pooled = {
        "added_ms_mean": float(np.mean([r["ms_per_frame"]["added"] for r in rows])),
        "added_ms_worst_motion": float(np.max([r["ms_per_frame"]["added"] for r in rows])),
        "surface_percent_mean": float(np.average([r["surface"]["surface"]["percent_mean"] for r in rows],
                                                 weights=[r["frames"] for r in rows])),
        "surface_percent_worst": float(np.max([r["surface"]["surface"]["percent_worst"] for r in rows])),
        "deepest_mm": float(np.max([r["surface"]["surface"]["deepest_mm"] for r in rows])),
    }
    met = {"added_ms": pooled["added_ms_worst_motion"] <= TARGETS["added_ms"],
           "surface_percent_mean": pooled["surface_percent_mean"] <= TARGETS["surface_percent_mean"],
           "surface_percent_worst": pooled["surface_percent_worst"] <= TARGETS["surface_percent_worst"],
           "deepest_mm": pooled["deepest_mm"] <= TARGETS["deepest_mm"]}
    print("pooled:", pooled, "targets met:", met)
    save_results(args.out, {"garment": {"kind": "skirt", "edge_m": args.edge, "length_m": args.length,
                                        "vertices": V, "input": "body-LBS (skinned rest skirt)"},
                            "surface_passes": args.passes, "surface_tolerance_m": SURFACE_TOLERANCE,
                            "depth_m": DEPTH, "torch_threads": 1, "repeats": args.repeats, "targets": TARGETS,
                            "targets_met": met, "pooled": pooled, "rows": rows})


if __name__ == "__main__":
    main()
