"""Does the canonical frame's origin on the floor cost accuracy in the air?

The per-garment networks predict the garment in the heading frame (:mod:`loosefit.models.motion_features`):
origin under the root on the floor, so in a jump the network itself must lift the garment with the body
(the root height is one of its inputs). If that were where jumps lose accuracy, the prediction would lag
the body vertically in flight: a vertical offset of the whole garment, which an origin at the root's full
position would remove. This measures it on trained runs, per held-out sequence:

- ``rmse_airborne_mm`` / ``rmse_grounded_mm``: RMSE over the frames whose root is more than 5 cm above its
  median height (in the air) and over the others;
- ``mean_dz_airborne_mm`` / ``mean_dz_grounded_mm``: the mean vertical offset of the prediction from the
  simulation (the mean over vertices of the z difference, then over those frames); a network that failed
  to lift the garment would show tens of millimetres here, negative;
- ``vertical_shift_share``: the share of the mean squared error that a per-frame vertical shift of the whole
  garment explains (what a root-relative origin could at most remove);
- ``corr_rootz_dz``: correlation of the root's height with that vertical offset over the frames.

Run: .venv/bin/python benchmarks/experiments/jump_height.py --data DATA.zarr --runs RUNS/<garment> [--methods virtualbones,jointnet]
         [--name jump-height]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import save_results  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402

#: Root height above its median (m) from which a frame counts as airborne.
AIRBORNE = 0.05


def height_scores(pred: np.ndarray, gt: np.ndarray, root_z: np.ndarray) -> dict:
    """Scores of ``pred`` against ``gt`` ``(T, V, 3)`` metres given the root's height ``(T,)`` (module doc)."""
    diff = pred - gt
    sq = (diff**2).sum(-1)
    dz = diff[..., 2].mean(1)
    air = root_z - np.median(root_z) > AIRBORNE
    out = {"rmse_mm": 1e3 * float(np.sqrt(sq.mean())), "vertical_shift_share": float((dz**2).mean() / sq.mean()),
           "airborne_frames": int(air.sum()), "rmse_grounded_mm": 1e3 * float(np.sqrt(sq[~air].mean())),
           "mean_dz_grounded_mm": 1e3 * float(dz[~air].mean()), "corr_rootz_dz": float(np.corrcoef(root_z, dz)[0, 1])}
    if air.any():
        out.update(rmse_airborne_mm=1e3 * float(np.sqrt(sq[air].mean())), mean_dz_airborne_mm=1e3 * float(dz[air].mean()))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="the store the runs were trained on")
    parser.add_argument("--runs", required=True, help="a folder holding one run folder per method")
    parser.add_argument("--methods", default="virtualbones,jointnet")
    parser.add_argument("--name", default="jump-height")
    args = parser.parse_args()
    store = DatasetStore.open(args.data)
    results: dict = {"data": str(Path(args.data).resolve()), "runs": str(Path(args.runs).resolve()),
                     "airborne_m": AIRBORNE, "sequences": {}}
    for method in args.methods.split(","):
        animator = Animator(Path(args.runs) / method)
        for name in store.sequence_names(split="test"):
            if store.sequence(name).garment != animator.meta["garment"]:
                continue
            seq = store.sequence(name)
            motion = store.motion(seq.motion)
            scores = height_scores(animator.animate(motion), np.asarray(seq.verts[:]), motion.translation[:, 2])
            results["sequences"][f"{method}/{seq.motion}"] = scores
    save_results(args.name, results)


if __name__ == "__main__":
    main()
