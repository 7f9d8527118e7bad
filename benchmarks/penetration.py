"""How much of an animated garment ends up inside the body on motions outside the training set, with the
collision handling ``loosefit animate`` applies by default and without it, and what that handling costs.

For each run and motion the garment is animated as ``loosefit animate RUN --motion M`` does with its defaults
(:class:`~loosefit.animate.Animator` with the best checkpoint, one torch thread, on the CPU; then
:func:`~loosefit.models.collision.handle_motion_collisions` in mode ``exact``, margin 0), and measured with
:func:`~loosefit.metrics.collision.inside_body_report`'s measure (vertices more than 5 mm inside the body's collision
proxy) on every frame, against the same animation with ``--collision none``; then against the full-resolution body,
at the vertices and at points between them (:func:`~loosefit.metrics.collision.surface_samples`: edge midpoints and
triangle centroids, where a limb through a triangle shows). Frames per second: the model alone
(``--collision none``) and the model plus the handling, both timed on a second, warm pass.

    python benchmarks/penetration.py --run vb=/work/stores/demo/runs/vb-e2 \\
        --run jn=/work/stores/pen-runs/jointnet \\
        --run swingar=/work/stores/runs/node-centred-alpha-2-seed-0@/work/stores/swingar-attention.zarr:skirt-6+average

``NAME=RUN`` for a one-garment run (VirtualBones, JointNet, body-LBS); ``NAME=RUN@DATA.zarr:GARMENT`` for a
multi-garment run (SwinGar) animating ``GARMENT`` of a store (a garment it never trained on). Motions:
``--motion kind:seed:seconds`` (procedural) or a BVH / motion file (``--joint-map cc`` for the CMU clips of
``../shared/mocap``). Writes ``benchmarks/results/penetration.json``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from _common import save_results
from loosefit.metrics.collision import penetrations

DEFAULT_MOTIONS = ["walk:1234:4", "spin:1234:4"]
DEFAULT_BVH = Path(__file__).resolve().parents[2] / "shared" / "mocap" / "cmu-cc" / "007_01.bvh"


def load_motions(specs: list[str], body, joint_map: str | None) -> dict:
    """``{label: Motion}`` for ``kind:seed:seconds`` specs and motion files."""
    from loosefit.motion.io import load_motion
    from loosefit.motion.procedural import generate

    motions = {}
    for spec in specs:
        parts = spec.split(":")
        if len(parts) == 3 and not Path(spec).exists():
            kind, seed, seconds = parts[0], int(parts[1]), float(parts[2])
            motions[f"{kind}-seed{seed}-{seconds:g}s"] = generate(kind, seconds, seed, body)
        else:
            motions[Path(spec).stem] = load_motion(spec, body, joint_map=joint_map if spec.endswith(".bvh") else None)
    return motions


def parse_run(spec: str) -> tuple[str, Path, object]:
    """``NAME=RUN`` or ``NAME=RUN@DATA.zarr:GARMENT`` -> name, run folder, garment (None or a Garment)."""
    name, _, rest = spec.partition("=")
    run, _, garment = rest.partition("@")
    if not garment:
        return name, Path(run), None
    from loosefit.data import DatasetStore

    data, _, gname = garment.rpartition(":")
    with DatasetStore.open(data) as store:
        return name, Path(run), store.garment(gname)


def animate_as_cli(run: Path, garment, body, motion, passes: int):
    """What ``loosefit animate RUN --motion M [--garment G]`` computes with its defaults, split into its two
    timed steps: ``(animator, raw (T, V, 3), corrected (T, V, 3), model seconds, handling seconds)``; ``passes``: the
    handling's surface passes at most."""
    from loosefit.animate import Animator
    from loosefit.models.collision import handle_motion_collisions

    animator = Animator(run, checkpoint="best", threads=1, garment=garment, body=body if garment is not None else None,
                        device="cpu")
    animator.animate_batch([motion])  # warm-up pass: first-call allocations are not what a frame costs
    t = time.perf_counter()
    raw = animator.animate_batch([motion])[0]
    t_model = time.perf_counter() - t
    handle = dict(mode="exact", margin=0.0, passes=passes, rest=animator.rest_garment)
    handle_motion_collisions(raw, animator.faces, body, motion, **handle)  # warm-up (kernels)
    t = time.perf_counter()
    fixed = handle_motion_collisions(raw, animator.faces, body, motion, **handle)
    t_coll = time.perf_counter() - t
    return animator, raw, fixed, t_model, t_coll


def main() -> None:
    from loosefit.body import AnnyBody, AnnyShape
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", action="append", required=True, help="NAME=RUN or NAME=RUN@DATA.zarr:GARMENT")
    ap.add_argument("--motion", action="append", default=None,
                    help="kind:seed:seconds or a motion file (default: walk and spin, seed 1234, 4 s, and CMU 07_01)")
    ap.add_argument("--joint-map", default="cc", help="joint map of BVH motions (default cc: ../shared/mocap)")
    ap.add_argument("--passes", type=int, default=None, help="surface passes at most (default: the handling's)")
    ap.add_argument("--out", default="penetration")
    args = ap.parse_args()
    from loosefit.models.collision import SURFACE_PASSES

    passes = SURFACE_PASSES if args.passes is None else args.passes

    body = AnnyBody(AnnyShape.parse(None))  # loosefit animate's body without --shape
    specs = args.motion or DEFAULT_MOTIONS + ([str(DEFAULT_BVH)] if DEFAULT_BVH.is_file() else [])
    motions = load_motions(specs, body, args.joint_map)
    proxy = body.collision_proxy()
    # each motion posed once for every run: the proxy (inside_body_report's measure) and the full body (what a
    # viewer sees)
    posed = {label: ((proxy.pose(m).verts, proxy.faces), (body.pose(m).verts, body.faces))
             for label, m in motions.items()}
    rows = []
    for spec in args.run:
        name, run, garment = parse_run(spec)
        for label, motion in motions.items():
            animator, raw, fixed, t_model, t_coll = animate_as_cli(run, garment, body, motion, passes)
            T = len(raw)
            on_proxy, on_full = posed[label]
            before, after = _per_frame(raw, *on_proxy), _per_frame(fixed, *on_proxy)
            full = _per_frame(fixed, *on_full)
            # between the vertices: edge midpoints and triangle centroids (a limb through a triangle), and the
            # deepest point, vertices and samples, handled and raw (evaluate's and report's measure)
            handled, unhandled = penetrations([(fixed, animator.faces), (raw, animator.faces)], on_full[0], on_full[1])
            surface, surface_none = handled.surface_percent, unhandled.surface_percent
            moved = np.linalg.norm(fixed - raw, axis=-1)
            row = {
                "run": name, "run_dir": str(run), "method": animator.method, "motion": label, "frames": T,
                "vertices": int(raw.shape[1]), "garment": None if garment is None else garment.name,
                "collision": "exact",
                "inside_5mm_percent_mean": float(after.mean()), "inside_5mm_percent_worst": float(after.max()),
                "worst_frame": int(np.argmax(after)),
                "full_body_inside_5mm_percent_mean": float(full.mean()),
                "full_body_inside_5mm_percent_worst": float(full.max()),
                "surface_inside_5mm_percent_mean": float(surface.mean()),
                "surface_inside_5mm_percent_worst": float(surface.max()),
                "none_surface_inside_5mm_percent_mean": float(surface_none.mean()),
                "none_surface_inside_5mm_percent_worst": float(surface_none.max()),
                "deepest_mm": float(1e3 * handled.deepest_m.max()), "none_deepest_mm": float(1e3 * unhandled.deepest_m.max()),
                "moved_mm_max": float(1e3 * moved.max()), "moved_mm_mean_of_moved": float(1e3 * moved[moved > 0].mean())
                if (moved > 0).any() else 0.0,
                "none_inside_5mm_percent_mean": float(before.mean()),
                "none_inside_5mm_percent_worst": float(before.max()), "none_worst_frame": int(np.argmax(before)),
                "fps_none": T / t_model, "fps_exact": T / (t_model + t_coll),
                "model_ms_per_frame": 1e3 * t_model / T, "collision_ms_per_frame": 1e3 * t_coll / T,
                "floor_met": bool(after.mean() <= 1.0),
            }
            rows.append(row)
            pct = lambda key: f"{row[key + '_mean']:5.2f} % (worst {row[key + '_worst']:5.2f} %)"  # noqa: E731
            print(f"{name:10s} {label:22s} inside>5mm {pct('inside_5mm_percent')}, "
                  f"none {pct('none_inside_5mm_percent')}, full body {pct('full_body_inside_5mm_percent')}, "
                  f"between vertices {pct('surface_inside_5mm_percent')}, "
                  f"none {pct('none_surface_inside_5mm_percent')}; deepest {row['deepest_mm']:.1f} mm "
                  f"(none {row['none_deepest_mm']:.1f}); {row['fps_exact']:.0f} fps with, "
                  f"{row['fps_none']:.0f} without; handling {row['collision_ms_per_frame']:.1f} ms/frame", flush=True)
    save_results(args.out, {"depth_m": 0.005, "floor_percent": 1.0, "torch_threads": 1, "rows": rows,
                            "surface_passes": passes})


def _per_frame(verts, posed: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Percent of ``verts (T, N, 3)`` more than 5 mm inside the posed body ``posed (T, Vb, 3)``, per frame
    ``(T,)``."""
    from loosefit.metrics.collision import REPORT_DEPTH, collision_ratio_per_frame

    return collision_ratio_per_frame(verts, posed, faces, REPORT_DEPTH)


if __name__ == "__main__":
    main()
