"""How much of a garment's motion each canonical frame explains before any learning.

For each frame of :data:`loosefit.motion.heading.FRAMES` (heading, raised, pelvis), every simulated frame of the
store's training sequences is put in that frame and averaged: the mean canonical garment, what a network predicts
before it has learned anything (VirtualBones' bone outputs and JointNet's start from the training statistics). Its
RMSE (mm) on the training and validation sequences, put back in the world with each frame's own transform, says how
much the frame alone carries the garment with the body: a frame that follows the hips through a crouch leaves less
to learn. The test split is not read.

``--upper JOINT:ABOVE`` also scores the garment's vertices whose rest height is above body joint ``ABOVE`` (a
dress's bodice: ``Spine1:Spine``) on their own, once in the raised frame and once in ``JOINT``'s frame (its world
rotation and position: the chest), the measure of a frame per garment region.

Run: .venv/bin/python benchmarks/experiments/garment_frames.py --data real-dress.zarr [--garment NAME]
         [--upper Spine1:Spine] [--name garment-frames-dress]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import save_results  # noqa: E402

from loosefit.body import AnnyBody, AnnyShape  # noqa: E402
from loosefit.data import DatasetStore  # noqa: E402
from loosefit.motion.heading import FRAMES, motion_frames, to_canonical  # noqa: E402


def mean_garment_rmse_mm(canonical: dict[str, dict[str, np.ndarray]]) -> dict[str, float]:
    """``{split: {sequence: (T, V, 3) canonical}}`` -> ``{split: RMSE (mm)}`` of the training mean garment,
    pooled over the vertices of every frame of the split (the frame is rigid: canonical error = world error)."""
    mean = np.concatenate(list(canonical["train"].values())).astype(np.float64).mean(0)
    out = {}
    for split, sequences in canonical.items():
        sq = np.concatenate([((v - mean) ** 2).sum(-1).ravel() for v in sequences.values()])
        out[split] = float(1000.0 * np.sqrt(sq.mean()))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--garment", default=None, help="default: the store's first garment")
    ap.add_argument("--upper", default=None, metavar="JOINT:ABOVE", help="score the part above joint ABOVE alone, "
                    "in the raised frame and in JOINT's frame")
    ap.add_argument("--name", default="garment-frames")
    a = ap.parse_args()
    store = DatasetStore.open(a.data)
    garment = a.garment or store.garment_names()[0]
    sequences = {split: [n for n in store.sequence_names(split=split) if store.sequence(n).garment == garment]
                 for split in ("train", "val")}
    world = {split: {n: (store.motion(store.sequence(n).motion), np.asarray(store.sequence(n).verts[:]))
                     for n in names} for split, names in sequences.items()}
    results = {"data": str(Path(a.data).resolve()), "garment": garment,
               "sequences": {k: len(v) for k, v in sequences.items()}, "mean_garment_rmse_mm": {}}
    for frame in FRAMES:
        canonical = {split: {n: to_canonical(v, *motion_frames(m, frame)) for n, (m, v) in seqs.items()}
                     for split, seqs in world.items()}
        results["mean_garment_rmse_mm"][frame] = row = mean_garment_rmse_mm(canonical)
        print(f"{frame:8s} train {row['train']:6.1f} mm   validation {row['val']:6.1f} mm", flush=True)
    if a.upper:
        results["upper"] = upper_part(store, garment, world, *a.upper.split(":"))
    print(save_results(a.name, results))


def upper_part(store, garment: str, world: dict, joint: str, above: str) -> dict:
    """The mean-garment RMSE (mm) of the garment's vertices above body joint ``above`` at rest: in the raised frame
    and in body joint ``joint``'s world frame (the posed joint's rotation and position; the average body's rig)."""
    first = store.sequence(next(iter(world["train"])))
    body = AnnyBody(AnnyShape.from_array(store.body(first.body)), resolution="low")
    names = list(body.joint_names)
    upper = store.garment(garment).verts[:, 2] > body.rest_joints()[names.index(above), 2]
    j = names.index(joint)
    canonical = {"raised": {}, joint: {}}
    for split, seqs in world.items():
        canonical["raised"][split] = {n: to_canonical(v, *motion_frames(m, "raised"))[:, upper]
                                      for n, (m, v) in seqs.items()}
        canonical[joint][split] = {}
        for n, (m, v) in seqs.items():
            T = body.pose(m).joint_transforms[:, j].astype(np.float64)
            canonical[joint][split][n] = np.einsum("tji,tvj->tvi", T[:, :3, :3], v[:, upper] - T[:, None, :3, 3])
    out = {"joint": joint, "above": above, "vertices": int(upper.sum())}
    for frame, parts in canonical.items():
        out[frame] = row = mean_garment_rmse_mm(parts)
        print(f"{int(upper.sum())} vertices above {above}, {frame:8s} train {row['train']:6.1f} mm   "
              f"validation {row['val']:6.1f} mm", flush=True)
    return out


if __name__ == "__main__":
    main()
