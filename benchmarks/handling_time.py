"""CPU time of the exact collision handling (``loosefit animate --collision exact``) per frame, by part, and the
quality it is judged by, on the shipped garments over validation clips of real capture.

For each shipped run (``pretrained:skirt`` = VirtualBones, ``pretrained:skirt/jointnet``, the dress's likewise) and clip
(``006_08``, ``006_09`` of ``../shared/mocap/cmu-cc``, joint map ``cc``) the garment is animated as
``loosefit animate`` does (one torch thread), then :func:`~loosefit.models.collision.handle_motion_collisions`
(mode ``exact``, the skinned fallback from the run's rest garment) runs ``--repeats`` times after a warm-up; the
CPU time of all threads (``time.process_time``) is split by wrapping the parts (posing and enclosing, the distance tree or mesh, the cull, closest points, the
winding number; the rest is the resolver's own bookkeeping). Quality, against the posed full-resolution body:
surface samples (vertices, edge midpoints, triangle centroids) more than 5 mm inside (% mean, % worst frame), the
deepest point (mm), and how far vertices move that were more than 5 mm outside the body before the handling
(collateral moves), triangles stretched or collapsed against the rest garment. ``--set`` changes a constant
of the handling for a run of this script (a lever). ``--reference FILE.npz`` compares the handled vertices with a
saved run (``--save``).

    PYTHONPATH=src nice -n 19 python benchmarks/handling_time.py --out handling-time
"""

from __future__ import annotations

import argparse
import os
import subprocess
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from _common import machine, save_results

MOCAP = Path(__file__).resolve().parents[2] / "shared" / "mocap" / "cmu-cc"
RUNS = {"vb": "pretrained:skirt", "jn": "pretrained:skirt/jointnet",
        "dress-vb": "pretrained:dress", "dress-jn": "pretrained:dress/jointnet"}
CLIPS = ["006_08", "006_09"]
#: ``(module, owner, attribute, part)``: what is wrapped to split the handling's time (absent ones are skipped).
PARTS = [
    ("loosefit.models.collision.handling", None, "enclosing_frames", "enclose"),
    ("loosefit.models.collision.handling", None, "inflated", "enclose"),
    ("loosefit.geometry.signed_distance", "BodySDF", "__init__", "tree"),
    ("loosefit.geometry.signed_distance", "PosedBodySDF", "__init__", "tree"),
    ("loosefit.geometry.signed_distance", "BodySDF", "closest", "closest"),
    ("loosefit.geometry.signed_distance", "BodySDF", "inside", "winding"),
    ("loosefit.geometry.ray_cull", "AxisRayCuller", "update", "cull"),
    ("loosefit.geometry.ray_cull", "AxisRayCuller", "outside", "cull"),
    ("loosefit.geometry.warp_sdf", "MotionMeshSDF", "__init__", "tree"),
    ("loosefit.geometry.warp_sdf", "MotionMeshSDF", "refit", "tree"),
    ("loosefit.geometry.warp_sdf", "MotionMeshSDF", "query", "closest+sign"),
]


class PartTimer:
    """Wraps :data:`PARTS`; ``spent[part]`` CPU seconds, the outermost wrapped call only (no double counting)."""

    def __init__(self):
        import importlib

        self.spent, self.depth, self.undo = defaultdict(float), 0, []
        for module, owner, attr, part in PARTS:
            try:
                mod = importlib.import_module(module)
            except ImportError:
                continue
            holder = getattr(mod, owner, None) if owner else mod
            if holder is None or attr not in vars(holder):
                continue
            self.undo.append((holder, attr, vars(holder)[attr]))
            setattr(holder, attr, self._wrap(vars(holder)[attr], part))

    def _wrap(self, fn, part):
        def timed(*args, **kwargs):
            if self.depth:
                return fn(*args, **kwargs)
            self.depth += 1
            t = time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self.spent[part] += time.process_time() - t
                self.depth -= 1
        return timed

    def restore(self):
        for holder, attr, fn in self.undo:
            setattr(holder, attr, fn)


def loadavg() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip().split("load average:")[-1].strip()


def quality(raw, fixed, faces, posed_full, body_faces, rest) -> dict:
    """Surface inside %, deepest mm, the moves of vertices that were > 5 mm outside the full body, and the shares
    of triangles (over frames) stretched past 4 times or collapsed under 20 % of their area on ``rest``."""
    from loosefit.geometry.normals import face_cross
    from loosefit.geometry.signed_distance import posed_body_sdfs
    from loosefit.metrics.collision import penetrations

    area = np.linalg.norm(face_cross(fixed, faces), axis=-1) / np.linalg.norm(face_cross(rest, faces), axis=-1)

    handled, none = penetrations([(fixed, faces), (raw, faces)], posed_full, body_faces)
    clear = np.stack([m.query(r) > 0.005 for m, r in zip(posed_body_sdfs(posed_full, body_faces), raw)])
    move = np.linalg.norm(fixed - raw, axis=-1)[clear]
    return {"surface_inside_5mm_percent_mean": float(handled.surface_percent.mean()),
            "surface_inside_5mm_percent_worst": float(handled.surface_percent.max()),
            "deepest_mm": float(1e3 * handled.deepest_m.max()),
            "none_surface_inside_5mm_percent_mean": float(none.surface_percent.mean()),
            "none_deepest_mm": float(1e3 * none.deepest_m.max()),
            "stretched_percent": float(100 * (area > 4).mean()), "collapsed_percent": float(100 * (area < 0.2).mean()),
            "clear_moved_percent": float(100 * (move > 0).mean()),
            "clear_moved_mm_mean": float(1e3 * move.mean()), "clear_moved_mm_max": float(1e3 * move.max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", default=None, help="result name under benchmarks/results (none: not written)")
    ap.add_argument("--cache", default="/tmp/loosefit-handling-raw", help="folder caching the raw animations")
    ap.add_argument("--save", default=None, help="save the handled vertices to this .npz")
    ap.add_argument("--reference", default=None, help="compare the handled vertices with this .npz")
    ap.add_argument("--no-quality", action="store_true")
    ap.add_argument("--backend", default="auto", help="exact_backend of handle_motion_collisions: auto, warp, igl")
    ap.add_argument("--clips", default=",".join(CLIPS))
    ap.add_argument("--runs", default=",".join(RUNS))
    ap.add_argument("--set", action="append", default=[], metavar="MODULE.NAME=VALUE",
                    help="a constant of loosefit.models.collision (for example resolver.SURFACE_TOLERANCE=0.001)")
    args = ap.parse_args()
    import ast
    import importlib

    for item in args.set:
        name, value = item.split("=", 1)
        module, attr = name.rsplit(".", 1)
        mod = importlib.import_module(f"loosefit.models.collision.{module}")
        setattr(mod, attr, type(getattr(mod, attr))(ast.literal_eval(value)))
    import torch

    from loosefit.animate import Animator
    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.models.collision import handle_motion_collisions
    from loosefit.motion.io import load_motion

    torch.set_num_threads(1)
    body = AnnyBody(AnnyShape.parse(None))
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    reference = dict(np.load(args.reference)) if args.reference else {}
    saved, rows = {}, []
    for clip in args.clips.split(","):
        motion = load_motion(str(MOCAP / f"{clip}.bvh"), body, joint_map="cc")
        posed_full = None
        for name in args.runs.split(","):
            run = RUNS[name]
            key = f"{name}-{clip}"
            path = cache / f"{key}.npz"
            if not path.exists():
                animator = Animator(run, checkpoint="best", threads=1, device="cpu")
                np.savez(path, raw=animator.animate_batch([motion])[0], faces=animator.faces,
                         rest=animator.rest_garment)
            data = np.load(path)
            raw, faces, rest = data["raw"], data["faces"], data["rest"]
            handle = dict(mode="exact", exact_backend=args.backend, rest=rest)  # as loosefit animate
            handle_motion_collisions(raw, faces, body, motion, **handle)  # warm-up (kernels, caches)
            spent, totals = defaultdict(float), []
            for _ in range(args.repeats):
                timer = PartTimer()
                t = time.process_time()
                fixed = handle_motion_collisions(raw, faces, body, motion, **handle)
                totals.append(time.process_time() - t)
                timer.restore()
                for part, s in timer.spent.items():
                    spent[part] += s / args.repeats
            T = len(raw)
            row = {"run": run, "clip": clip, "backend": args.backend, "set": args.set, "frames": T,
                   "vertices": int(raw.shape[1]),
                   "load": loadavg(),
                   "ms_per_frame": 1e3 * min(totals) / T, "ms_per_frame_each": [1e3 * s / T for s in totals],
                   "parts_ms_per_frame": {p: 1e3 * s / T for p, s in sorted(spent.items())}}
            row["parts_ms_per_frame"]["rest"] = 1e3 * np.mean(totals) / T - sum(row["parts_ms_per_frame"].values())
            saved[key] = fixed
            if key in reference:
                diff = np.linalg.norm(fixed - reference[key], axis=-1)
                row["vs_reference_mm_max"] = float(1e3 * diff.max())
                row["vs_reference_vertices_over_0.1mm"] = int((diff > 1e-4).sum())
            if not args.no_quality:
                if posed_full is None:
                    posed_full = body.pose(motion).verts
                row.update(quality(raw, fixed, faces, posed_full, body.faces, rest))
            rows.append(row)
            print(key, {k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items()
                        if k not in ("run",)}, flush=True)
    if args.save:
        np.savez(args.save, **saved)
    if args.out:
        save_results(args.out, {"machine": machine(), "timer": "time.process_time (all threads)",
                                "os_cpu_count": os.cpu_count(), "rows": rows})


if __name__ == "__main__":
    main()
