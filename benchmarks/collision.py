"""SwinGar's collision handling (Sec. III-D, Eqs. 7-10) on a simulated store: collision ratio (Table II),
Laplacian consistency of the correction (Table III) and the correction's time per frame on a CPU.

1. The body SDF network (SwinGar Eqs. 8-9) is trained on the store's training bodies and motions
   (``loosefit train --method collision``; ``--set train.steps=...`` sets the CPU budget), or read from
   ``--sdf-run`` when that folder already holds one (a finished run is resumed, never retrained).
2. Every test sequence is animated with ``--run`` (SwinGar or any method ``loosefit animate`` supports;
   its predictions were trained with the collision loss alone, SwinGar Eq. 14) and corrected four ways:
   ``none``, ``eq10-neural`` (SwinGar Eq. 10 with the network), ``eq10-exact`` (Eq. 10 with libigl's exact
   distance) and ``pushout`` (every inside vertex moved to the surface plus ``--push-distance``, TailorNet's
   post-process), all through :func:`loosefit.models.collision.handle_motion_collisions` on the sequence's
   posed collision proxy. ``--margin`` (ours): Eq. 10 (neural) on the network's surface moved that far out
   (:func:`~loosefit.models.collision.handle_motion_collisions`).
3. Per method and garment kind (the garment entry's name before '-': skirt, dress, long_shirt, jumpsuit):
   the collision ratio, % of garment vertices deeper than ``--tolerance`` inside the posed collision proxy by
   the exact signed distance, averaged over frames (and the same against the full-resolution body, for
   reference), and the Laplacian consistency deviation ``d_cons = |diag(L) - diag(L^C)|`` (half-cotangent
   Laplacians before and after the correction) averaged over the corrected vertices only; the paper's
   numbers beside them (its T-shirt row stands for our long_shirt). Targets: Eq. 10 (neural) removes at
   least 80 % of the collisions left by the collision loss alone; its d_cons is below push-out's.
4. Speed: the correction of one frame of a garment of about 10k vertices (each kind present, on the average
   body, skinned by its closest body vertices along the first test motion), 1 and 2 torch threads, each
   design tried: the paper's way (the network's value and autograd gradient at every vertex), with
   denormals flushed, with the cull (:class:`~loosefit.geometry.ray_cull.AxisRayCuller`), smaller networks
   trained on the same samples for the same steps (``--speed-widths``) or read from other runs
   (``--speed-sdf-runs``), bfloat16, the exact SDF, and a whole motion in chunks of frames in one or two threads
   (:func:`~loosefit.models.collision.correct_motion`, what ``loosefit animate --collision`` runs), also with
   other cull bins (``--cull-cells``). The
   accuracy of each network against libigl on near-surface points of the test bodies goes beside its time.

Run: .venv/bin/python benchmarks/collision.py --data STORE --run RUN [--sdf-run DIR] [--set train.steps=N]
(writes benchmarks/results/<--name>.json; default name ``collision``)
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
from _common import save_results  # noqa: E402

#: SwinGar Table II: average % of garment vertices inside the body on new motions.
PAPER_TABLE_II = {
    "long_shirt": {"collision loss only": 0.97, "SSCH": 0.10, "w/ collision handling": 0.12},
    "dress": {"collision loss only": 0.61, "SSCH": 0.07, "w/ collision handling": 0.07},
    "jumpsuit": {"collision loss only": 1.18, "SSCH": 0.14, "w/ collision handling": 0.15},
}
#: SwinGar Table III: mean Laplacian consistency deviation over the collision-corrected vertices.
PAPER_TABLE_III = {
    "long_shirt": {"TailorNet": 0.56, "ReFu": 0.47, "Ours": 0.34},
    "dress": {"TailorNet": 0.30, "ReFu": 0.28, "Ours": 0.21},
    "jumpsuit": {"TailorNet": 0.63, "ReFu": 0.55, "Ours": 0.42},
}
PAPER_NOTES = ("Table II/III rows 'T-shirt' are SwinGar's long t-shirts, shown beside our long_shirt; SwinGar reports "
               "its correction at about 0.2 ms per frame (Sec. V-B, hardware not stated; training used two RTX A6000).")
METHODS = ("none", "eq10-neural", "eq10-exact", "pushout")
#: Targets: Eq. 10 (neural) removes at least this fraction of the collision loss's collisions (SwinGar: 88 %).
MIN_REDUCTION = 0.8
#: The benchmark's speed floor for 10k vertices on a CPU, ms per frame.
FLOOR_MS = 1.0


def kind_of(garment_entry: str) -> str:
    """Garment kind from a store entry name: ``dress-3+heavy`` -> ``dress``."""
    return garment_entry.split("+")[0].split("-")[0]


# ------------------------------------------------------------------------------------------------- SDF network


def sdf_network(data: Path, sdf_run: Path, config: str | None, overrides: list[str]):
    """The body SDF of ``sdf_run`` (trained there first when the folder has none) and its ``model.json``."""
    from loosefit.config import load_config
    from loosefit.models.collision import SDF_FILE, SDF_META, SDFRunConfig, load_body_sdf, train_sdf_run

    if not (sdf_run / SDF_FILE).is_file():
        start = time.perf_counter()
        summary = train_sdf_run(data, sdf_run, load_config(SDFRunConfig, config, overrides), progress=True)
        summary["train_wall_s"] = time.perf_counter() - start
        (sdf_run / SDF_META).write_text(json.dumps(summary, indent=2))
    summary = json.loads((sdf_run / SDF_META).read_text())
    return load_body_sdf(sdf_run / SDF_FILE), summary


# ------------------------------------------------------------------------------------------- Tables II and III


def margin_of(sdf_run: Path, value: str) -> float:
    """``--margin`` in metres: the number, or with ``auto`` the run's calibrated margin (measured now and added to
    its ``model.json`` when a run trained before runs measured it)."""
    from loosefit.errors import InputError
    from loosefit.models.collision import SDF_META, calibrate_sdf_run, collision_margin

    try:
        if value.strip().lower() == "auto" and not json.loads((sdf_run / SDF_META).read_text()).get("calibration"):
            calibrate_sdf_run(sdf_run)
        return collision_margin(sdf_run, value)
    except InputError as e:
        sys.exit(f"collision.py: {e}")


def evaluate_sequence(seq, pred: np.ndarray, net, tolerance: float, push_distance: float, margin: float,
                      cull_cell: float) -> dict:
    """Every method on one sequence: per-frame collision % (proxy and full body), d_cons sums, wall time."""
    from loosefit.geometry.signed_distance import BodySDF
    from loosefit.metrics.collision import collision_ratio_per_frame
    from loosefit.metrics.surface import laplacian_consistency
    from loosefit.models.collision import handle_motion_collisions

    proxy = seq.body.collision_proxy()
    posed = proxy.pose(seq.motion).verts
    proxy_sdfs = [BodySDF(v, proxy.faces) for v in posed]
    full_sdfs = [BodySDF(v, seq.body_faces) for v in seq.body_verts]
    out = {}
    for method in METHODS:
        start = time.perf_counter()
        if method == "none":
            verts = pred
        else:
            mode = {"eq10-neural": "neural", "eq10-exact": "exact", "pushout": "pushout"}[method]
            verts = handle_motion_collisions(pred, seq.faces, seq.body, seq.motion, mode, net, push_distance,
                                             margin=margin, cull_cell=cull_cell)  # margin: neural only
        wall = time.perf_counter() - start
        moved = np.any(verts != pred, axis=-1)  # (T, V) the corrected vertices
        row = {"collision_pct_frames": collision_ratio_per_frame(verts, proxy_sdfs, tolerance=tolerance).tolist(),
               "collision_full_body_pct_frames": collision_ratio_per_frame(verts, full_sdfs, tolerance=tolerance).tolist(),
               "corrected": int(moved.sum()), "ms_per_frame": 1e3 * wall / len(pred)}
        row["d_cons_values"] = np.zeros(0)  # left out of the JSON
        if moved.any():
            d = laplacian_consistency(pred, verts, seq.faces)
            row["d_cons_values"] = d[moved]
            row["displacement_mm_sum"] = float(1e3 * np.linalg.norm(verts - pred, axis=-1)[moved].sum())
        out[method] = row
    return out


def summarise(rows: list[dict]) -> dict:
    """Per kind (and ``all``) and method: mean collision % over frames, d_cons and displacement over the
    corrected vertex-frames."""
    kinds = sorted({r["kind"] for r in rows}) + ["all"]
    table = {}
    for kind in kinds:
        mine = [r for r in rows if kind in ("all", r["kind"])]
        if not mine:
            continue
        entry = {"sequences": len(mine), "frames": int(sum(len(r["methods"]["none"]["collision_pct_frames"]) for r in mine))}
        for method in METHODS:
            cells = [r["methods"][method] for r in mine]
            frames = np.concatenate([c["collision_pct_frames"] for c in cells])
            full = np.concatenate([c["collision_full_body_pct_frames"] for c in cells])
            count = sum(c["corrected"] for c in cells)
            d = np.concatenate([c["d_cons_values"] for c in cells])
            entry[method] = {"collision_pct": float(frames.mean()), "collision_full_body_pct": float(full.mean()),
                             "corrected_vertex_frames": count,
                             "d_cons": float(d.mean()) if count else None,
                             "d_cons_median": float(np.median(d)) if count else None,
                             "d_cons_p95": float(np.percentile(d, 95)) if count else None,
                             "mean_displacement_mm": (sum(c.get("displacement_mm_sum", 0.0) for c in cells) / count
                                                      if count else None),
                             "ms_per_frame": float(np.mean([c["ms_per_frame"] for c in cells]))}
        none = entry["none"]["collision_pct"]
        entry["reduction_eq10_neural"] = 1 - entry["eq10-neural"]["collision_pct"] / none if none > 0 else None
        entry["paper_table_ii"] = PAPER_TABLE_II.get(kind)
        entry["paper_table_iii"] = PAPER_TABLE_III.get(kind)
        table[kind] = entry
    return table


def targets(table: dict) -> list[dict]:
    out = []
    for kind, e in table.items():
        red = e["reduction_eq10_neural"]
        out.append({"target": f"{kind}: Eq. 10 (neural) removes >= {MIN_REDUCTION:.0%} of the collisions left by the "
                              "collision loss alone", "value": red, "pass": None if red is None else red >= MIN_REDUCTION,
                    "note": None if red is not None else "no collision to remove"})
        ours, push = e["eq10-neural"]["d_cons"], e["pushout"]["d_cons"]
        out.append({"target": f"{kind}: d_cons of Eq. 10 (neural) below push-out's", "value": [ours, push],
                    "pass": None if ours is None or push is None else ours < push,
                    "note": None if ours is not None and push is not None else "a method corrected nothing"})
    return out


# ----------------------------------------------------------------------------------------------------- speed


def garment_10k(kind: str, body, target: int = 10000):
    """A template garment of ``kind`` with about ``target`` vertices on ``body`` (vertex count ~ 1/edge^2)."""
    from loosefit.garment import make_garment

    edge = 0.015
    for _ in range(3):
        g = make_garment(kind, body, seed=0, edge_length=edge)
        if abs(g.num_verts - target) < 0.08 * target:
            break
        edge = float(np.clip(edge * np.sqrt(g.num_verts / target), 0.006, 0.06))
    return g


def skinned(garment, body, motion) -> np.ndarray:
    """``(T, V, 3)``: the garment skinned with the weights of its closest rest body vertex (body-LBS)."""
    from loosefit.geometry.features import nearest_body_vertex
    from loosefit.geometry.lbs import linear_blend_skinning, skinning_transforms

    posed = body.pose(motion)
    weights = body.skinning_weights()[nearest_body_vertex(garment.verts, body.rest_verts())]
    A = skinning_transforms(torch.from_numpy(posed.joint_transforms).double(), torch.from_numpy(body.rest_joints()).double())
    return linear_blend_skinning(torch.from_numpy(garment.verts).double(), torch.from_numpy(weights).double(),
                                 A).numpy().astype(np.float32)


def time_frames(fn, frames: list[int], reps: int) -> dict:
    """``fn(t)`` timed: per frame the fastest of ``reps`` calls (the machine is shared), then the median and
    the worst of those over the frames, and the median of every call; ms."""
    calls = np.zeros((reps, len(frames)))
    for r in range(reps):
        for k, t in enumerate(frames):
            start = time.perf_counter()
            fn(t)
            calls[r, k] = time.perf_counter() - start
    best = calls.min(0)
    return {"ms_per_frame": float(1e3 * np.median(best)), "ms_per_frame_worst_frame": float(1e3 * best.max()),
            "ms_per_frame_median_all_calls": float(1e3 * np.median(calls)), "frames": len(frames), "reps": reps}


def time_motion(fn, num_frames: int, reps: int) -> dict:
    """``fn()`` corrects a whole motion of ``num_frames``: the fastest of ``reps`` calls and their median, ms a
    frame."""
    fn()  # warm (thread pool, kernels)
    calls = []
    for _ in range(reps):
        start = time.perf_counter()
        fn()
        calls.append(time.perf_counter() - start)
    return {"ms_per_frame": float(1e3 * min(calls) / num_frames),
            "ms_per_frame_median_all_calls": float(1e3 * np.median(calls) / num_frames), "frames": num_frames,
            "reps": reps}


class Bf16Bound:
    """A :class:`~loosefit.models.collision.BoundBodySDF` evaluated in bfloat16 (values returned as float32)."""

    def __init__(self, bound):
        self.bound = bound
        to = lambda pairs: [(w.bfloat16(), b.bfloat16()) for w, b in pairs]  # noqa: E731
        self.point, self.fusion = to(bound.point), to(bound.fusion)
        self.first_bias = bound.first_bias.bfloat16()

    def __call__(self, points: torch.Tensor) -> torch.Tensor:
        b = self.bound
        h = points.bfloat16()
        first = h = b._act(torch.nn.functional.linear(h, *self.point[0]))
        for w, c in self.point[1:]:
            h = b._act(torch.nn.functional.linear(h, w, c))
        if len(self.point) > 1:
            h = h + first
        z = torch.nn.functional.linear(h, self.fusion[0][0], self.first_bias)
        for w, c in self.fusion[1:]:
            z = torch.nn.functional.linear(b._act(z), w, c)
        return z[..., 0].float()


def near_surface_set(shapes, motions, frames: int, points: int, seed: int = 0) -> dict:
    """Near-surface points of posed bodies in the canonical frame with libigl's signed distance: ``points
    (P, N, 3)``, ``sdf (P, N)``, ``code (P, C)`` (the test bodies and motions, none of them trained on)."""
    from loosefit.models.collision import SDFTrainConfig, body_sdf_samples

    cfg = SDFTrainConfig(frames=frames, surface=0, near=points, inside=0, near_sigma=0.01, seed=seed)
    return body_sdf_samples(shapes, motions, cfg)


def sdf_accuracy(net_or_bound_fn, test: dict, bone_frames: bool) -> dict:
    """Error of a field against libigl on ``test``: mean / p95 absolute (mm), sign agreement (%), also within
    5 mm of the surface. ``net_or_bound_fn(code) -> SDFFunction``; ``bone_frames``: its codes end with them."""
    from loosefit.models.collision import samples_code

    err, agree, err5 = [], [], []
    for pts, sdf, code in zip(test["points"], test["sdf"], samples_code(test, bone_frames)):
        with torch.no_grad():
            pred = net_or_bound_fn(torch.from_numpy(code))(torch.from_numpy(pts)).float().numpy()
        e = np.abs(pred - sdf)
        err.append(e)
        agree.append((pred < 0) == (sdf < 0))
        err5.append(e[np.abs(sdf) < 0.005])
    err, agree, err5 = np.concatenate(err), np.concatenate(agree), np.concatenate(err5)
    return {"mean_abs_mm": float(1e3 * err.mean()), "p95_abs_mm": float(1e3 * np.percentile(err, 95)),
            "sign_agree_pct": float(100 * agree.mean()), "within_5mm_mean_abs_mm": float(1e3 * err5.mean()),
            "points": int(err.size)}


def speed(net, sdf_summary: dict, store, test_seqs, kinds: list[str], widths: list[int], width_steps: int,
          frames: int, reps: int, threads_list: list[int], other_nets: dict | None,
          cull_cells: list | None, margin: float, cull_cell: float) -> dict:
    """Time per frame of the correction of ~10k vertices, each design tried (see the module docstring); the
    culled designs (rows 3, 6, 7) with the network's surface moved out by ``margin`` metres, as corrected, and
    bins of ``cull_cell`` metres (rows 3, 5, 6). ``other_nets``: ``{name: (network, its margin)}``."""
    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.geometry.ray_cull import AxisRayCuller
    from loosefit.geometry.signed_distance import BodySDF
    from loosefit.models.collision import (BodySDFConfig, BodySDFNet, CollisionResolver, ExactSDF,
                                           SDFTrainConfig, body_sdf_samples, correct_frame, correct_motion,
                                           flushed_denormals, motion_sdf_inputs, sdf_and_gradient, train_body_sdf)
    from loosefit.motion.heading import to_canonical
    from loosefit.threads import torch_threads

    body = AnnyBody()
    proxy = body.collision_proxy()
    motion = test_seqs[0].motion
    posed = proxy.pose(motion).verts
    bones = net.num_bones > 0  # the narrower networks below are trained with the same config
    codes, rot, origin = motion_sdf_inputs(body, motion, bone_frames=True)  # the bone frames follow the plain code
    code = codes[:, :net.code_size]
    picks = [int(t) for t in np.linspace(0, motion.num_frames - 1, frames).round()]
    out: dict = {"motion": test_seqs[0].motion.name, "body": "average Anny, collision proxy 1,229 vertices",
                 "cull_cell_m": cull_cell, "frames_timed": picks, "garments": {}}

    # networks: the trained one and narrower ones fitted to the same samples for the same steps
    cfg = SDFTrainConfig(**sdf_summary["config"])
    nets = {f"trained (hidden {net.config.hidden})": (net, margin), **(other_nets or {})}  # name: (network, margin)
    if widths:
        train_names = store.sequence_names(split="train")
        shapes = [AnnyShape.from_array(store.body(b)) for b in sorted({store.sequence(n).body for n in train_names})]
        motions = [store.motion(m) for m in sorted({store.sequence(n).motion for n in train_names})]
        samples = body_sdf_samples(shapes, motions, cfg)
        for h in widths:
            start = time.perf_counter()
            with torch_threads(1):
                small, history = train_body_sdf(samples, SDFTrainConfig(**{**vars(cfg), "steps": width_steps}),
                                                BodySDFConfig(**{**sdf_summary["net"], "hidden": h}))
            nets[f"hidden {h}"] = (small.eval(), margin)
            out.setdefault("width_training", {})[f"hidden {h}"] = {"steps": width_steps, "final_loss": history[-1],
                                                                  "wall_s": time.perf_counter() - start}
    test_shapes = [s.body.shape for s in test_seqs]
    test = near_surface_set(list({tuple(s.to_array()): s for s in test_shapes}.values()),
                            list({s.motion.name: s.motion for s in test_seqs}.values()), frames=4, points=2000)
    out["accuracy_near_surface"] = {name: sdf_accuracy(lambda c, n=n: n.bind(c), test, n.num_bones > 0)
                                    for name, (n, _) in nets.items()}
    out["accuracy_near_surface"]["trained, bfloat16"] = sdf_accuracy(lambda c: Bf16Bound(net.bind(c)), test, bones)
    if net.config.hidden != 512:  # the paper's size for the paper-way timing (untrained weights)
        torch.manual_seed(0)
        nets_paper = BodySDFNet(net.code_size, BodySDFConfig(**{**sdf_summary["net"], "hidden": 512}),
                                net.num_bones).eval()
    else:
        nets_paper = net

    for kind in kinds:
        garment = garment_10k(kind, body)
        verts = skinned(garment, body, motion)
        culler = AxisRayCuller(posed[0], proxy.faces, cull_cell)
        inside = [int((BodySDF(posed[t], proxy.faces).query(verts[t]) < 0).sum()) for t in picks]
        row = {"vertices": garment.num_verts, "inside_per_frame_exact": float(np.mean(inside)),
               "candidates_per_frame": float(np.mean([(~culler.update(posed[t], verts[t]).outside(verts[t])).sum() for t in picks]))}
        resolver = CollisionResolver(garment.faces, garment.num_verts)
        resolver.sigma = resolver.mean_edge(torch.from_numpy(verts[0]))
        cell_cullers = {str(c): AxisRayCuller(posed[0], proxy.faces, c) for c in cull_cells or []}
        row["candidates_per_frame_by_cull_bins"] = {
            cell: float((~c.update(posed, verts).outside(verts)).sum() / len(verts)) for cell, c in cell_cullers.items()}
        for threads in threads_list:
            timing = {}
            with torch_threads(threads):
                canonical = to_canonical(verts, rot, origin)

                def value_grad_all(t):  # the library before: the value and autograd gradient at every vertex
                    sdf_and_gradient(lambda p: nets_paper(p[None], code[t][None])[0], torch.from_numpy(canonical[t]))

                slow = picks[:2]
                size = f"hidden {nets_paper.config.hidden}" + ("" if nets_paper is net else ", untrained")
                timing[f"1 before ({size}): value + autograd gradient at every vertex"] = time_frames(value_grad_all, slow, 1)
                with flushed_denormals():
                    timing[f"1b before ({size}), denormals flushed"] = time_frames(value_grad_all, slow, 1)
                for name, (n, m) in nets.items():
                    n_code = codes[:, :n.code_size]
                    bound = n.bind(n_code[0])
                    moved_out = bound.offset(m)
                    timing[f"2 {name}: bound code, hand gradient, denormals flushed, every vertex"] = time_frames(
                        lambda t: correct_frame(verts[t], resolver, bound.with_code(n_code[t]), (rot[t], origin[t])),
                        slow, 1)
                    timing[f"3 {name}: + axis-ray cull"] = time_frames(
                        lambda t: correct_frame(verts[t], resolver, moved_out.with_code(n_code[t]), (rot[t], origin[t]),
                                                culler.update(posed[t], verts[t])), picks, reps)
                    for workers in (1, 2):  # the whole motion, chunks of frames (what loosefit animate runs)
                        timing[f"6 {name}: + a motion's frames a pass, {workers} worker(s)"] = time_motion(
                            lambda: correct_motion(verts, resolver, n, n_code, rot, origin, posed, culler, m,
                                                   workers=workers), motion.num_frames, reps)
                    for cell, other in cell_cullers.items():  # the same with other bins
                        timing[f"7 {name}: a motion, 2 workers, cull bins {cell} m"] = time_motion(
                            lambda: correct_motion(verts, resolver, n, n_code, rot, origin, posed, other, m),
                            motion.num_frames, reps)
                b32 = net.bind(code[0])
                bf = Bf16Bound(b32)
                cand = {t: ~culler.update(posed[t], verts[t]).outside(verts[t]) for t in picks}
                with flushed_denormals():
                    timing["4 trained, bfloat16 forward on the cull's candidates (value only)"] = time_frames(
                        lambda t: bf(torch.from_numpy(canonical[t][cand[t]])), picks, reps)
                    timing["4b trained, float32 forward on the same candidates (value only)"] = time_frames(
                        lambda t: b32(torch.from_numpy(canonical[t][cand[t]])), picks, reps)
                timing["5 exact SDF (libigl tree per frame) + axis-ray cull"] = time_frames(
                    lambda t: correct_frame(verts[t], resolver, ExactSDF(BodySDF(posed[t], proxy.faces)), None,
                                            culler.update(posed[t], verts[t])), picks, reps)
                timing["5b exact SDF (libigl tree per frame), every vertex"] = time_frames(
                    lambda t: correct_frame(verts[t], resolver, ExactSDF(BodySDF(posed[t], proxy.faces))), picks[:3], 1)
                timing["cull alone: update + query"] = time_frames(
                    lambda t: culler.update(posed[t], verts[t]).outside(verts[t]), picks, reps)
            row[f"threads_{threads}"] = timing
        out["garments"][kind] = row
    pose_start = time.perf_counter()
    proxy.pose(motion)
    out["posing_proxy_ms_per_frame"] = 1e3 * (time.perf_counter() - pose_start) / motion.num_frames
    return out


def speed_targets(speed_result: dict) -> list[dict]:
    """Per garment kind, the fastest neural design frame by frame (rows 3, streaming) and over a whole motion
    (rows 6, the post-process of loosefit animate; its fastest uses two worker threads, one a core), at 1 torch
    thread (per worker)."""
    out = []
    for kind, row in speed_result["garments"].items():
        timing = row.get("threads_1", {})
        for prefix, how in (("3 ", "frame by frame (streaming)"),
                            ("6 ", "a whole motion in chunks of frames, 1 or 2 worker threads (the CPU's 2 cores)")):
            culled = {k: v["ms_per_frame"] for k, v in timing.items() if k.startswith(prefix)}
            if not culled:
                continue
            best = min(culled, key=culled.get)
            out.append({"target": f"{kind} ({row['vertices']} vertices): correction under {FLOOR_MS} ms a frame, "
                                  f"neural SDF, 1 torch thread, {how}", "value": culled[best], "design": best,
                        "pass": culled[best] < FLOOR_MS})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="the simulated dataset store")
    parser.add_argument("--run", required=True, help="a trained garment model run (e.g. SwinGar)")
    parser.add_argument("--sdf-run", default=None, help="body SDF run folder: read when it holds a network, else "
                        "trained there (default: <work>/sdf)")
    parser.add_argument("--work", default="/tmp/collision-bench")
    parser.add_argument("--config", default=None, help="SDF run config YAML (loosefit train --method collision)")
    parser.add_argument("--set", action="append", default=[], help="SDF config override, e.g. train.steps=500")
    parser.add_argument("--tolerance", type=float, default=1e-3, help="collision depth tolerance, metres")
    parser.add_argument("--push-distance", type=float, default=0.004, help="push-out distance, metres")
    parser.add_argument("--margin", default="0",
                        help="Eq. 10 (neural) on the network's surface moved this many metres out (ours; the paper: 0); "
                             "'auto': the margin calibrated for the network (measured first if its run has none)")
    parser.add_argument("--skip-speed", action="store_true")
    parser.add_argument("--speed-only", action="store_true",
                        help="the speed part alone (no collision tables), e.g. to time on an idle machine")
    parser.add_argument("--speed-widths", default="32,64,128", help="narrower networks to time ('' for none)")
    parser.add_argument("--speed-steps", type=int, default=None, help="their training steps (default: the SDF run's)")
    parser.add_argument("--speed-sdf-runs", default="",
                        help="other trained SDF run folders to time beside it (comma), each with its --margin")
    parser.add_argument("--cull-cell", type=float, default=None,
                        help="the cull's bin side of every correction and timed design, metres (default: CULL_CELL)")
    parser.add_argument("--cull-cells", default="", help="other cull bin sizes to time over a motion, metres: "
                        "';'-separated, each one size or 'x,y,z' (e.g. '0.015,0.015,0.03;0.02,0.02,0.04')")
    parser.add_argument("--speed-frames", type=int, default=12)
    parser.add_argument("--speed-reps", type=int, default=5)
    parser.add_argument("--threads", default="1,2", help="torch thread counts of the speed part")
    parser.add_argument("--name", default="collision", help="results file name")
    args = parser.parse_args()
    from loosefit.models.collision import CULL_CELL

    args.cull_cell = args.cull_cell or CULL_CELL
    if args.speed_only and args.skip_speed:
        parser.error("--speed-only and --skip-speed leave nothing to do")

    from loosefit.data.store import DatasetStore
    from loosefit.report.predictions import animate_run, load_sequences
    from loosefit.threads import torch_threads

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    data = Path(args.data)
    sdf_run = Path(args.sdf_run) if args.sdf_run else work / "sdf"
    with torch_threads(1):
        net, sdf_summary = sdf_network(data, sdf_run, args.config, args.set)
        net.eval()
        margin_arg, args.margin = args.margin, margin_of(sdf_run, args.margin)
        sequences = load_sequences(data, split="test")
        method, predictions = animate_run(args.run, sequences)
        rows = []
        for seq in sequences:
            if seq.name not in predictions or args.speed_only:
                continue
            print(f"{seq.name}: {len(seq.gt)} frames, {seq.gt.shape[1]} vertices", flush=True)
            rows.append({"sequence": seq.name, "kind": kind_of(seq.garment), "vertices": int(seq.gt.shape[1]),
                         "methods": evaluate_sequence(seq, predictions[seq.name], net, args.tolerance, args.push_distance,
                                                      args.margin, args.cull_cell)})
    table = summarise(rows) if rows else {}
    results = {"data": str(data.resolve()), "run": str(Path(args.run).resolve()), "method": method,
               "sdf_run": str(sdf_run.resolve()), "sdf": {k: sdf_summary.get(k) for k in
                                                          ("bodies", "motions", "frames", "first_loss", "final_loss",
                                                           "config", "net", "train_wall_s")},
               "tolerance_m": args.tolerance, "push_distance_m": args.push_distance, "margin_m": args.margin,
               "cull_cell_m": args.cull_cell,
               "collision_body": "the posed collision proxy (1,229-vertex Anny), the body the SDF learns and every "
                                 "correction uses; collision_full_body_pct: the 13.7k-vertex body, for reference",
               "paper_notes": PAPER_NOTES, "per_kind": table, "targets": targets(table),
               "sequences": [{k: v for k, v in r.items() if k != "methods"} |
                             {m: {"collision_pct": float(np.mean(c["collision_pct_frames"])), "corrected": c["corrected"]}
                              for m, c in r["methods"].items()} for r in rows]}
    if not args.skip_speed:
        widths = [int(w) for w in args.speed_widths.split(",") if w.strip()]
        steps = args.speed_steps or int(sdf_summary["config"]["steps"])
        store = DatasetStore.open(data, "r")
        kinds = sorted({kind_of(s.garment) for s in sequences if s.name in predictions}) or ["dress"]
        from loosefit.models.collision import SDF_FILE, load_body_sdf

        others = {}
        for folder in filter(None, (f.strip() for f in args.speed_sdf_runs.split(","))):
            other = load_body_sdf(Path(folder) / SDF_FILE).eval()
            others[f"{Path(folder).name} (hidden {other.config.hidden})"] = (other, margin_of(Path(folder), margin_arg))
        results["speed"] = speed(net, sdf_summary, store, [s for s in sequences if s.name in predictions], kinds,
                                 widths, steps, args.speed_frames, args.speed_reps,
                                 [int(t) for t in args.threads.split(",")], others,
                                 [[float(v) for v in c.split(",")] if "," in c else float(c)
                                  for c in filter(None, (c.strip() for c in args.cull_cells.split(";")))],
                                 args.margin, args.cull_cell)
        results["speed"]["margin_m"] = args.margin
        results["speed"]["other_sdf_margins_m"] = {name: m for name, (_, m) in others.items()}
        results["targets"] += speed_targets(results["speed"])
    save_results(args.name, results)


if __name__ == "__main__":
    main()
