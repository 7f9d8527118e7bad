"""The prepare stage: time and peak memory of ``prepare`` for a ~6k-vertex garment over 3,000 training
frames with 80 bones, and SSDR error versus bone count (20, 40, 80, 150) on the bench dress.

- Timing: a dataset with the bench dress remeshed to about ``--vertices`` vertices and ``--frames``
  training frames, 300-frame procedural motions; the garment's frames are the dress skinned to the
  body (``loosefit.sim.attach``), not simulated, since simulating 3,000 frames would cost more than
  what is measured (``--data`` times a simulated dataset instead). ``prepare`` runs in a child
  process, so its peak resident memory is its own.
- Bone sweep: the bench dress (``configs/datasets/bench.yaml``: seed 0, 0.025 m edges, length
  0.8 m) simulated on a spin and a walk of ``--sweep-seconds`` each (or the training sequences of
  garment ``dress`` of ``--data``), low-frequency split, SSDR with each bone count on all frames:
  RMSE against the low-frequency meshes (what the bones are fitted to) and against the full meshes.

Run: .venv/bin/python benchmarks/prepare.py [--frames 3000] [--vertices 6000] [--bones 80]
         [--sweep 20,40,80,150] [--sweep-seconds 5] [--data DATA.zarr] [--skip-timing] [--skip-sweep]
(writes benchmarks/results/prepare.json)
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

from loosefit.body import AnnyBody  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.garment import make_garment  # noqa: E402
from loosefit.geometry.smoothing import frequency_split  # noqa: E402
from loosefit.motion.procedural import generate  # noqa: E402
from loosefit.rig.virtual_bones import DEFAULT_BONES, fit_virtual_bones, frame_errors, solve_bone_transforms  # noqa: E402

DRESS = {"length": 0.8}  # as in configs/datasets/bench.yaml
MOTION_KINDS = ("walk", "run", "spin", "jump", "kick", "squat", "bow", "wave", "sway", "mix")


def bench_dress(body, vertices: int | None = None):
    """The bench dress; with ``vertices``, remeshed to about that many (edge length from the area)."""
    edge = 0.025
    garment = make_garment("dress", body, seed=0, edge_length=edge, **DRESS)
    if vertices:
        for _ in range(2):
            edge = min(0.06, max(0.006, edge * (len(garment.verts) / vertices) ** 0.5))
            garment = make_garment("dress", body, seed=0, edge_length=edge, **DRESS)
    return garment


def timing_store(path: Path, body, vertices: int, frames: int) -> dict:
    """A dataset of one garment skinned to the body over ``frames`` training frames (300 per motion)."""
    from loosefit.sim.attach import garment_weights, skin_garment

    garment = bench_dress(body, vertices)
    store = DatasetStore.create(path)
    store.add_body("average", body.shape.to_array())
    store.add_garment("dress", garment)
    weights = garment_weights(garment.verts, body)
    for i in range(int(np.ceil(frames / 300))):
        count = min(300, frames - 300 * i)
        motion = generate(MOTION_KINDS[i % len(MOTION_KINDS)], count / 30.0, i, body)
        name = f"{MOTION_KINDS[i % len(MOTION_KINDS)]}-{i}"
        store.add_motion(name, motion)
        verts = skin_garment(garment.verts, weights, body, motion)
        store.write_sequence(name, verts, "dress", "average", name, {}, {}, "train")
    return {"vertices": len(garment.verts), "frames": frames, "frames_from": "garment skinned to the body"}


def time_prepare(path: Path, bones: int) -> dict:
    """Run ``prepare`` in a child process; wall time and the child's peak resident memory."""
    code = (
        "import json, sys; from loosefit.rig.prepare import prepare; "
        f"print(json.dumps(prepare({str(path)!r}, bones={bones}, progress=False), default=str))"
    )
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"prepare failed:\n{done.stderr[-3000:]}")
    peak_kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    summary = json.loads(done.stdout.splitlines()[-1])
    return {"bones": bones, "wall_s": wall, "peak_rss_mb": peak_kib / 1024, "summary": summary}


def sweep_frames(body, seconds: float, data: str | None):
    """``(garment, [frames (T, V, 3)], {sequence: status})``: the bench dress simulated, or the ``dress``
    training sequences of ``data``."""
    if data:
        store = DatasetStore.open(data)
        names = [n for n in store.sequence_names(split="train") if store.sequence(n).garment == "dress"]
        return store.garment("dress"), [store.sequence(n).verts[:] for n in names], {n: "ok" for n in names}
    from loosefit.sim import SimParams, simulate_sequence

    garment = bench_dress(body)
    frames, status = [], {}
    for kind in ("spin", "walk"):
        result = simulate_sequence(garment, body, generate(kind, seconds, 0, body), SimParams())
        ms = result.stats["ms_per_frame"]
        print(f"simulated {kind}: {result.status} {result.reason} {ms:.0f} ms/frame", flush=True)
        frames.append(result.verts)
        status[kind] = f"{result.status} {result.reason}".strip()
    return garment, frames, status


def bone_sweep(garment, sequences: list[np.ndarray], counts: list[int]) -> list[dict]:
    low = np.concatenate([frequency_split(f, garment.faces)[0] for f in sequences])
    full = np.concatenate(sequences)
    rest = frequency_split(garment.verts, garment.faces)[0]
    rows = []
    for bones in counts:
        start = time.perf_counter()
        rig, R, T = fit_virtual_bones(low, rest, garment.faces, bones=bones, max_solve_frames=len(low))
        fitted = time.perf_counter() - start
        R, T = solve_bone_transforms(rig, low, R, T)
        row = {
            "bones_requested": bones,
            "bones": rig.num_bones,
            "rmse_lf_mm": float(np.sqrt(frame_errors(rig, low, R, T).mean()) * 1e3),
            "rmse_full_mm": float(np.sqrt(frame_errors(rig, full, R, T).mean()) * 1e3),
            "fit_s": fitted,
            "total_s": time.perf_counter() - start,
        }
        rows.append(row)
        print(f"{bones:4d} bones: {row['rmse_lf_mm']:.2f} mm (low frequency), {row['rmse_full_mm']:.2f} mm (full), "
              f"{row['total_s']:.0f} s", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=3000, help="training frames of the timing dataset")
    parser.add_argument("--vertices", type=int, default=6000, help="garment size of the timing dataset")
    parser.add_argument("--bones", type=int, default=DEFAULT_BONES, help="bones of the timed prepare")
    parser.add_argument("--sweep", default="20,40,80,150", help="bone counts of the error sweep")
    parser.add_argument("--sweep-seconds", type=float, default=5.0, help="length of each simulated sweep motion")
    parser.add_argument("--data", help="a simulated dataset: time prepare on a copy, sweep its garment 'dress'")
    parser.add_argument("--skip-timing", action="store_true")
    parser.add_argument("--skip-sweep", action="store_true")
    args = parser.parse_args()
    body = AnnyBody()
    results: dict = {"load_average_at_start": os.getloadavg()}
    if not args.skip_timing:
        with tempfile.TemporaryDirectory(prefix="loosefit-bench-") as tmp:
            path = Path(tmp) / "data.zarr"
            if args.data:
                import shutil

                shutil.copytree(args.data, path)
                results["timing_dataset"] = {"source": args.data}
            else:
                results["timing_dataset"] = timing_store(path, body, args.vertices, args.frames)
            print(f"timing prepare on {results['timing_dataset']} ...", flush=True)
            results["timing"] = time_prepare(path, args.bones)
            timing = results["timing"]
            print(f"prepare: {timing['wall_s']:.0f} s, peak {timing['peak_rss_mb']:.0f} MB", flush=True)
    if not args.skip_sweep:
        garment, sequences, status = sweep_frames(body, args.sweep_seconds, args.data)
        results["sweep_dataset"] = {"vertices": len(garment.verts), "frames": int(sum(len(f) for f in sequences)),
                                    "source": args.data or "bench dress simulated on spin and walk",
                                    "simulation_status": status}
        results["sweep"] = bone_sweep(garment, sequences, [int(b) for b in args.sweep.split(",")])
    results["load_average_at_end"] = os.getloadavg()
    save_results("prepare", results)


if __name__ == "__main__":
    main()
