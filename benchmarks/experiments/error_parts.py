"""Where a trained garment's error lies: the wrong average drape for a whole sequence, or the wrong swing about it.

Each run animates the store's sequences from frame 0 (as ``loosefit animate``); prediction and simulation are put in
the garment's moving frame (``--frame``, the raised frame by default, the same for every run) and their RMSE is split
(:func:`loosefit.metrics.errors.error_parts_mm`) into the sequence's mean-shape error and the error of the motion
about it, beside how much the simulation itself moves about its average. Pooled over a split by the sum of squares.
The test split is read only with ``--score-test``.

Run: .venv/bin/python benchmarks/experiments/error_parts.py --data real-dress.zarr \
         --run virtualbones=runs/dress+average/virtualbones --run jointnet=... [--name error-parts-dress]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import save_results  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.data import DatasetStore  # noqa: E402
from loosefit.metrics.errors import error_parts_mm  # noqa: E402
from loosefit.motion.heading import FRAMES, motion_frames, to_canonical  # noqa: E402

PARTS = ("total", "mean_shape", "motion", "simulated_motion")


def pooled(rows: list[dict]) -> dict[str, float]:
    """The parts of several sequences pooled as one RMSE each: the root of the frame-weighted mean square."""
    frames = np.array([r["frames"] for r in rows], float)
    return {k: float(np.sqrt((frames * np.array([r[k] for r in rows]) ** 2).sum() / frames.sum())) for k in PARTS}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--run", action="append", required=True, metavar="NAME=PATH")
    ap.add_argument("--garment", default=None, help="default: the store's first garment")
    ap.add_argument("--frame", default="raised", choices=FRAMES)
    ap.add_argument("--score-test", action="store_true")
    ap.add_argument("--name", default="error-parts")
    a = ap.parse_args()
    store = DatasetStore.open(a.data)
    splits = ("train", "val", "test") if a.score_test else ("train", "val")
    runs = dict(r.split("=", 1) for r in a.run)
    garment = a.garment or store.garment_names()[0]
    results = {"data": str(Path(a.data).resolve()), "garment": garment, "frame": a.frame, "runs": runs, "splits": {}}
    animators = {name: Animator(path) for name, path in runs.items()}
    for split in splits:
        rows: dict[str, list] = {name: [] for name in runs}
        for seq_name in store.sequence_names(split=split):
            seq = store.sequence(seq_name)
            if seq.garment != garment:
                continue
            # the simulation read and put in the garment's frame once, for every run
            motion = store.motion(seq.motion)
            frame = motion_frames(motion, a.frame)
            simulated = to_canonical(np.asarray(seq.verts[:]), *frame)
            for name, animator in animators.items():
                parts = error_parts_mm(to_canonical(animator.animate(motion), *frame), simulated)
                rows[name].append({"sequence": seq_name, "frames": len(simulated), **parts})
        for name, sequences in rows.items():
            if not sequences:
                continue
            entry = {"pooled": pooled(sequences), "sequences": sequences}
            results["splits"].setdefault(split, {})[name] = entry
            p = entry["pooled"]
            print(f"{name:14s} {split:5s} total {p['total']:6.1f}  mean shape {p['mean_shape']:6.1f}  motion "
                  f"{p['motion']:6.1f}  (the simulation moves {p['simulated_motion']:6.1f}) mm", flush=True)
    print(save_results(a.name, results))


if __name__ == "__main__":
    main()
