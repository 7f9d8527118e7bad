"""Can a mirrored simulation stand in for a new one? Left-right mirroring as training data, measured.

Mirroring a simulated sequence through the body's plane of symmetry (the motion by
:func:`loosefit.motion.mirror.mirror_motion`, the garment frames by :class:`loosefit.data.mirror.GarmentMirror`)
would double the training data without simulating anything, if the simulator's answer to the mirrored motion
were the mirror image of its answer to the motion. It is only for a symmetric garment. This script simulates the
mirrored motion of stored sequences (the store's garment, body and simulation parameters; the store's own run is
reproduced to the bit by the same call), reads the result back onto the garment's mesh, and compares it with the
stored run, beside what a second honest run differs by: the stored reference runs (10 micrometres of start noise)
and their floor, where the sequence has them.

Per sequence: ``mirror_rmse_mm`` (the mirrored simulation, read back, against the stored run), per second and at
frame 0 (the garment settled on the first pose, before the motion has moved it), ``reference_rmse_mm`` (each
reference run against the stored run) and ``floor_mm``; per garment, its ``asymmetry_mm`` at rest (each vertex's
mirror image's distance from the rest surface: mean, 95th percentile, max); and the body's own check (the full
body posed by the mirrored motion, read back the same way, against the body posed by the motion).

Run: .venv/bin/python benchmarks/experiments/mirror_symmetry.py --data STORE.zarr --sequences skirt+average+spin-1+default,...
         [--name mirror-symmetry]
(writes benchmarks/results/<name>.json after every sequence; conclusion in benchmarks/experiments/LOG.md)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import save_results  # noqa: E402


def rmse_mm(a: np.ndarray, b: np.ndarray) -> float:
    """:func:`loosefit.metrics.reference.rmse_m` of two ``(T, V, 3)`` runs, in mm to 0.01."""
    from loosefit.metrics.reference import rmse_m

    return round(1e3 * rmse_m(a, b), 2)


def mirrored_run(store, name: str) -> dict:
    """One stored sequence against the simulation of its mirrored motion (module docstring)."""
    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.data.mirror import GarmentMirror
    from loosefit.metrics.reference import References
    from loosefit.motion.mirror import joint_partners, mirror_motion
    from loosefit.sim.params import SimParams
    from loosefit.sim.sequence import simulate_sequence

    seq = store.sequence(name)
    garment = store.garment(seq.garment)
    body = AnnyBody(AnnyShape.from_array(store.body(seq.body)))
    motion = store.motion(seq.motion)
    partners = joint_partners(body.joint_names, body.rest_joints())
    result = simulate_sequence(garment, body, mirror_motion(motion, partners), SimParams.from_dict(seq.sim_params))
    base = np.asarray(seq.verts[:], np.float64)
    mirror = GarmentMirror.build(garment.verts, garment.faces)
    image = mirror(result.verts)
    body_mirror = GarmentMirror.build(body.rest_verts(), body.faces)
    row = {"frames": int(len(base)), "vertices": int(base.shape[1]),
           "mirror_rmse_mm": rmse_mm(image, base), "mirror_frame0_mm": rmse_mm(image[:1], base[:1]),
           "mirror_per_second_mm": [rmse_mm(image[a:a + 30], base[a:a + 30]) for a in range(0, len(base), 30)],
           "mirror_status": result.status,
           "body_check_mm": rmse_mm(body_mirror(result.body_verts), body.pose(motion).verts),
           "asymmetry_mm": {"mean": round(1e3 * float(mirror.asymmetry.mean()), 2),
                            "p95": round(1e3 * float(np.percentile(mirror.asymmetry, 95)), 2),
                            "max": round(1e3 * float(mirror.asymmetry.max()), 2)}}
    references = store.references(name)
    if len(references):
        runs = References(base, references)
        row.update(reference_rmse_mm=[rmse_mm(r, base) for r in references], floor_mm=round(runs.floor_mm, 2),
                   mirror_rmse_vs_mean_mm=round(runs.score(image).rmse_vs_mean_mm, 2))
    return row


def main(argv: list[str] | None = None) -> None:
    from loosefit.data.store import DatasetStore

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", required=True, help="a simulated store")
    parser.add_argument("--sequences", required=True, help="comma-separated sequence names")
    parser.add_argument("--name", default="mirror-symmetry")
    args = parser.parse_args(argv)
    store = DatasetStore.open(args.data, mode="r")
    results = {"data": str(args.data), "sequences": {}}
    for name in args.sequences.split(","):
        results["sequences"][name] = mirrored_run(store, name)
        print(name, results["sequences"][name], flush=True)
        save_results(args.name, results)


if __name__ == "__main__":
    main()
