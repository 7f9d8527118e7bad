"""Render stored sequences beside the runs' animations of their motions, one PNG per sequence at a chosen frame:
simulation | each run (no collision handling: the networks' own output), the body under each.

Run: .venv/bin/python scripts/render_clips.py --data DATA.zarr --runs RUNS/<garment> --out DIR SEQ:FRAME [SEQ:FRAME ...]
     (SEQ a sequence of the store; RUNS/<garment> holds one run folder per method, as benchmarks/accuracy.py leaves)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from loosefit.animate import Animator
from loosefit.data.store import DatasetStore
from loosefit.viz.inputs import dataset_panel
from loosefit.viz.render import render_video
from loosefit.viz.scene import GARMENT_COLOR, MeshTrack


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--runs", required=True, help="a folder of run folders, one per method")
    ap.add_argument("--methods", nargs="+", default=["virtualbones", "jointnet", "body-lbs"])
    ap.add_argument("--out", required=True)
    ap.add_argument("frames", nargs="+", metavar="SEQ:FRAME")
    a = ap.parse_args()
    store = DatasetStore.open(a.data)
    animators = {m: Animator(Path(a.runs) / m, device="cpu") for m in a.methods}
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    for spec in a.frames:
        seq, _, frame = spec.rpartition(":")
        sim = dataset_panel(a.data, seq)
        motion = store.motion(store.sequence(seq).motion)
        panels = [sim] + [[sim[0], MeshTrack(anim.animate(motion).astype(np.float32), sim[1].faces, GARMENT_COLOR,
                                              label=m)] for m, anim in animators.items()]
        path = out / f"{seq}-f{frame}.png"
        render_video(panels, path, frames=[int(frame)], size=(420, 560), progress=False)
        print("wrote", path)


if __name__ == "__main__":
    main()
