"""The pins' radius (``model.pin_radius``, :mod:`loosefit.models.pins`) on a store's validation sequences: the pooled
RMSE (mm, against the simulation) of each run's garment with no pins and with its garment's pins kept over each radius
(``--split test`` to report a choice made on validation, ``--name`` to save the JSON).

The network is the run's own (a run trained with pins or without: pins act where the garment is animated, not in
training); the pins are made anew for each radius from the store's garment and body (:func:`with_pins`).

    .venv/bin/python benchmarks/experiments/pin_radius.py --data real-dress-all.zarr \\
        --run virtualbones=pretrained:dress --run jointnet=pretrained:dress/jointnet [--radii 0,0.1,0.2,0.3,0.4]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

from loosefit.animate import load_run
from loosefit.body import AnnyBody, AnnyShape
from loosefit.data import DatasetStore
from loosefit.models.motion_features import motion_features
from loosefit.models.pins import with_pins
from loosefit.motion.heading import motion_frames, to_world

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import save_results  # noqa: E402


def pooled_rmse_mm(model, sequences: list, store) -> float:
    """Pooled RMSE (mm) of ``model``'s garment, its pins kept (if it has them), over ``sequences`` of ``store``."""
    total = count = 0.0
    for name in sequences:
        seq = store.sequence(name)
        motion = store.motion(seq.motion)
        f = motion_features(motion, model.history)
        root, joints = torch.from_numpy(f["root"])[None], torch.from_numpy(f["joints"])[None]
        with torch.no_grad():
            canonical = model.pinned(model(root, joints)["verts"], root, joints)[0].numpy()
        error = to_world(canonical, *motion_frames(motion, model.frame)) - np.asarray(seq.verts[:], np.float64)
        total += float((error ** 2).sum())
        count += error.shape[0] * error.shape[1]
    return 1000 * float(np.sqrt(total / count))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, help="a store with validation sequences of the runs' garment")
    ap.add_argument("--run", action="append", required=True, help="NAME=RUN (a run folder or pretrained:NAME)")
    ap.add_argument("--radii", default="0,0.1,0.2,0.3,0.4", help="radii in metres, comma-separated")
    ap.add_argument("--split", default="val", help="the store's split scored (default val; test only to report)")
    ap.add_argument("--name", default=None, help="also save the rows as benchmarks/results/<name>.json")
    a = ap.parse_args()
    store = DatasetStore.open(a.data)
    results = {}
    for spec in a.run:
        label, run = spec.split("=", 1)
        meta, model, _ = load_run(run)
        names = [n for n in store.sequence_names(split=a.split) if store.sequence(n).garment == meta["garment"]]
        first = store.sequence(names[0])
        body = AnnyBody(AnnyShape.from_array(store.body(first.body)), rig=store.motion(first.motion).rig)
        garment = store.garment(meta["garment"])
        model.pins = None  # no pins: the network's garment as it is
        row = {"none": pooled_rmse_mm(model.eval(), names, store)}
        for radius in (float(r) for r in a.radii.split(",")):
            row[str(radius)] = pooled_rmse_mm(with_pins(model, garment, body, radius).eval(), names, store)
        results[label] = row
        print(label, json.dumps({k: round(v, 2) for k, v in row.items()}), flush=True)
    if a.name:
        save_results(a.name, {"data": a.data, "split": a.split, "pooled_rmse_mm_by_radius": results})


if __name__ == "__main__":
    main()
