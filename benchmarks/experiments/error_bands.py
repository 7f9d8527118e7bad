"""Where a model's held-out error lives: the smooth shape (the bones' part) or the wrinkles, beside each one's floor.

For every test sequence of ``--garment`` with reference runs in ``--data``, each run given with ``--run LABEL=PATH``
animates the motion, and its prediction and the simulated runs are split by the filter that ``loosefit prepare``
uses on the simulated meshes (the rig's smoothing preset, pinned vertices kept;
:class:`loosefit.metrics.reference.BandedReferences`): the ``low`` band is the smooth garment (its swing, what
VirtualBones' bones carry, paper Sec. 3.2), ``high`` the wrinkles (its high-frequency module's part). The split is
linear and the bands barely overlap, so ``rmse^2`` is close to ``rmse_low^2 + rmse_high^2``; it applies to any
model's output the same way (VirtualBones' own low-frequency output is not used).

Each band is scored against the base run and against the mean of the runs, beside the band's floor (the runs' RMS
spread around their mean in that band), with the size of the wrinkles in the mean run (``signal/high_mm``: what a
perfect smooth garment without wrinkles would score against the mean in the high band). A band whose RMSE against
the mean is far above its floor is where the model, not the simulator's chaos, loses accuracy.

Run: .venv/bin/python benchmarks/experiments/error_bands.py --data DATA.zarr --garment skirt+average \\
         --run VirtualBones=RUNS/skirt+average/virtualbones --run JointNet=... [--name error-bands]
(writes benchmarks/results/<name>.json; keys ``figures/<motion>/<label>/{all,low,high}/{rmse_mm,rmse_vs_mean_mm}``,
``figures/<motion>/floor/{all,low,high}_mm`` and ``figures/<motion>/signal/high_mm``)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import save_results  # noqa: E402
from accuracy import held_out_sequences  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.errors import InputError  # noqa: E402
from loosefit.geometry.smoothing import frequency_split  # noqa: E402
from loosefit.metrics.reference import BandedReferences, rmse_m  # noqa: E402
from loosefit.rig.prepared import prepared_split  # noqa: E402


def band_split(store: DatasetStore, garment: str):
    """``split(x (T, V, 3)) -> (low, high)`` as the garment's rig was prepared (smoothing preset, pinned vertices)."""
    settings, smoothing, fixed = prepared_split(store, garment)
    if not settings:
        raise InputError(f"garment {garment} has no prepared rig (run loosefit prepare first)", store.path)
    faces = store.garment(garment).faces
    return lambda x: frequency_split(x, faces, smoothing, fixed=fixed)


def sequence_bands(store: DatasetStore, name: str, animators: dict, split) -> dict:
    """The bands of every animator on test sequence ``name`` (``{label: {band: {rmse_mm, rmse_vs_mean_mm}}}``),
    the floor of each band, and the size of the wrinkles in the mean run."""
    seq = store.sequence(name)
    refs = store.references(name)
    if len(refs) == 0:
        raise InputError(f"test sequence {name} has no reference runs (simulate the plan's references)", store.path)
    bands = BandedReferences(np.asarray(seq.verts[:], np.float32), refs, split)
    motion = store.motion(seq.motion)
    out = {}
    for label, animator in animators.items():
        scores = bands.score(animator.animate(motion))
        out[label] = {band: {"rmse_mm": s.rmse_mm, "rmse_vs_mean_mm": s.rmse_vs_mean_mm} for band, s in scores.items()}
    out["floor"] = {f"{band}_mm": r.floor_mm for band, r in bands.bands.items()}
    # what the smooth shape predicted perfectly and no wrinkles at all would score against the mean run
    out["signal"] = {"high_mm": 1e3 * rmse_m(bands.bands["high"].mean, np.zeros_like(bands.bands["high"].mean))}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="a prepared dataset with reference runs of its test sequences")
    parser.add_argument("--garment", required=True, help="the store's garment entry, e.g. skirt+average")
    parser.add_argument("--run", action="append", required=True, help="LABEL=RUN_FOLDER (repeatable)")
    parser.add_argument("--name", default="error-bands", help="results name: benchmarks/results/<name>.json")
    args = parser.parse_args()
    store = DatasetStore.open(Path(args.data))
    split = band_split(store, args.garment)
    if not all("=" in r for r in args.run):
        parser.error("--run takes LABEL=RUN_FOLDER")
    runs = dict(r.split("=", 1) for r in args.run)
    animators = {label: Animator(Path(path)) for label, path in runs.items()}
    names = held_out_sequences(store, args.garment)
    started = time.perf_counter()
    figures = {}
    for name in names:
        motion = store.sequence(name).motion
        figures[motion] = sequence_bands(store, name, animators, split)
        f = figures[motion]
        print(f"{motion}: floor low {f['floor']['low_mm']:.1f} high {f['floor']['high_mm']:.1f} "
              f"(wrinkles in the mean run {f['signal']['high_mm']:.1f}) mm; " + "; ".join(
                  f"{label} vs mean: low {f[label]['low']['rmse_vs_mean_mm']:.1f} high "
                  f"{f[label]['high']['rmse_vs_mean_mm']:.1f} all {f[label]['all']['rmse_vs_mean_mm']:.1f}"
                  for label in animators), flush=True)
    save_results(args.name, {"data": str(Path(args.data).resolve()), "garment": args.garment, "runs": runs,
                             "sequences": names, "figures": figures, "wall_s": time.perf_counter() - started})


if __name__ == "__main__":
    main()
