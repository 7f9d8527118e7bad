"""File size of the engine-ready rig (``loosefit export-rig``) against the per-frame exports of today.

For each trained run (VirtualBones, JointNet) and each motion length (a procedural walk), write:

- ``morph.glb``: ``loosefit animate --out x.glb --with-body`` (:mod:`loosefit.io.gltf`): garment and body
  as one morph target per frame;
- ``points.usdc``: the same as time-sampled points (:mod:`loosefit.io.usd`);
- ``rig4.glb`` / ``rig8.glb`` / ``rig4.usdc``: ``loosefit export-rig`` with 4 or 8 influences per vertex
  (garment skinned to its virtual bones, body to its skeleton, joint animation baked);

each with the body and garment-only, and report bytes, export seconds and the rig's truncation error
(4 influences against the full weights, over every frame). The morph exports hold the full prediction,
the rigs the low-frequency one: sizes are compared for the same frames and meshes.

Run: .venv/bin/python benchmarks/export_rig.py [--runs demo_out/runs] [--seconds 2 10 30] [--work /tmp/export-rig]
(needs the trained runs of ``make demo``; writes benchmarks/results/export_rig.json)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402


def _timed(function, *args, **kwargs):
    start = time.perf_counter()
    result = function(*args, **kwargs)
    return result, round(time.perf_counter() - start, 3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", default="demo_out/runs", help="folder with virtualbones/ and jointnet/ runs")
    parser.add_argument("--seconds", type=float, nargs="+", default=[2.0, 10.0, 30.0])
    parser.add_argument("--work", default="/tmp/export-rig", help="where the files are written")
    args = parser.parse_args()

    from loosefit.animate import Animator
    from loosefit.body import AnnyBody
    from loosefit.export_rig import export_rig
    from loosefit.io.export import export_animation
    from loosefit.motion.procedural import generate

    body = AnnyBody()
    work = Path(args.work)
    results = {"body_vertices": body.num_verts, "body_joints": body.num_joints, "runs": {}}
    for method in ("virtualbones", "jointnet"):
        run = Path(args.runs) / method
        animator = Animator(run)
        entry = {"run": str(run), "garment_vertices": int(animator.meta["sizes"]["num_verts"]),
                 "bones": int(animator.meta["sizes"]["num_bones"]), "motions": {}}
        for seconds in args.seconds:
            motion = generate("walk", seconds, 0, body)
            folder = work / method / f"{seconds:g}s"
            verts = animator.animate(motion)
            posed = body.pose(motion).verts
            sizes, times = {}, {}
            for with_body in (True, False):
                tag = "" if with_body else "_garment_only"
                extra = dict(body_verts=posed, body_faces=body.faces) if with_body else {}
                for name in ("morph.glb", "points.usdc"):
                    path = folder / f"{Path(name).stem}{tag}{Path(name).suffix}"
                    _, times[path.name] = _timed(export_animation, path, verts, animator.faces, motion.fps, **extra)
                    sizes[path.name] = path.stat().st_size
                for name, influences in (("rig4.glb", 4), ("rig8.glb", 8), ("rig4.usdc", 4)):
                    path = folder / f"{Path(name).stem}{tag}{Path(name).suffix}"
                    summary, times[path.name] = _timed(export_rig, run, motion, path, body=body if with_body else None,
                                                       influences=influences)
                    sizes[path.name] = summary["bytes"]
                    if influences == 4 and with_body and path.suffix == ".glb":
                        truncation = {k: {m: summary[k][m] for m in ("max_mm", "rms_mm", "vertices_truncated")}
                                      for k in ("garment", "body")}
            entry["motions"][f"walk_{seconds:g}s"] = {
                "frames": motion.num_frames, "bytes": sizes, "export_seconds": times,
                "morph_over_rig4_glb": round(sizes["morph.glb"] / sizes["rig4.glb"], 1),
                "points_over_rig4_usdc": round(sizes["points.usdc"] / sizes["rig4.usdc"], 1),
                "truncation_4_influences": truncation,
            }
            print(method, seconds, sizes, flush=True)
        results["runs"][method] = entry
    save_results("export_rig", results)


if __name__ == "__main__":
    main()
