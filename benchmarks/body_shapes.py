"""What each Anny shape key changes: the body's height and its girths at the chest, waist and hips, at 0 and 1 of
each key with the others at 0.5 (the average adult), against the average body.

Girths as :mod:`loosefit.body.measures` takes them (the convex hull of the torso within 1 cm of the upper spine
joint, the spine joint and the hip joints).

Run: .venv/bin/python benchmarks/body_shapes.py   (writes benchmarks/results/body-shapes.json)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import save_results  # noqa: E402

from loosefit.body.measures import measures  # noqa: E402


def main() -> None:
    from loosefit.body import AnnyBody, AnnyShape

    body = AnnyBody()
    results = {}
    base = None
    for key in [None, *AnnyShape.names()]:
        for value in ([0.5] if key is None else [0.0, 1.0]):
            shape = AnnyShape(**({} if key is None else {key: value}))
            verts, joints = body._rest_geometry(shape)
            m = measures(np.asarray(verts, np.float64), dict(zip(body.joint_names, np.asarray(joints, np.float64))))
            if base is None:
                base = m
            name = "average" if key is None else f"{key}={value:g}"
            results[name] = {**{k: round(v, 4) for k, v in m.items()},
                             **{f"change_{k}": round(m[k] - base[k], 4) for k in m}}
            print(name, {k: round(v, 3) for k, v in results[name].items()}, flush=True)
    save_results("body-shapes", results)


if __name__ == "__main__":
    main()
