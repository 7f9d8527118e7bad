"""A body's height and girths, as a tailor takes them: what tells two body shapes apart for a garment.

Girths are perimeters of the convex hull of the rest body's vertices within 1 cm of a joint's height (chest: the
upper spine joint ``Spine1``; waist: ``Spine``; hips: the hip joints ``LeftUpLeg``), keeping only the torso: the
vertices laterally inside 90 % of the shoulder joints' half-width (the rest pose holds the arms out, beyond it).
Anny's ``cmu_mb`` joint names.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

#: Girth -> the joint at whose height it is taken.
LEVELS = {"chest": "Spine1", "waist": "Spine", "hips": "LeftUpLeg"}


def measures(verts: np.ndarray, joints: dict[str, np.ndarray]) -> dict[str, float]:
    """Height (m) and girths (cm) of a rest body ``verts (V, 3)`` (Z up) with rest ``joints`` (name -> (3,)):
    ``height_m``, ``chest_girth_cm``, ``waist_girth_cm``, ``hips_girth_cm``."""
    height = float(verts[:, 2].max() - verts[:, 2].min())
    out = {"height_m": height}
    centre = joints["Hips"][0]
    torso = np.abs(verts[:, 0] - centre) < 0.9 * abs(joints["LeftArm"][0] - joints["RightArm"][0]) / 2
    for name, joint in LEVELS.items():
        ring = verts[torso & (np.abs(verts[:, 2] - joints[joint][2]) < 0.01)][:, :2]
        out[f"{name}_girth_cm"] = float(ConvexHull(ring).area * 100)  # in 2-D, ``area`` is the perimeter
    return out


def shape_measures(body, shape=None) -> dict[str, float]:
    """:func:`measures` of an Anny ``body`` in ``shape`` (its own when ``None``)."""
    verts, joints = body.rest_verts(shape), body.rest_joints(shape)
    return measures(np.asarray(verts, np.float64), dict(zip(body.joint_names, np.asarray(joints, np.float64))))
