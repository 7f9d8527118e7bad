"""The axes of a source skeleton's world: which way is up and which way the character faces."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from loosefit.errors import InputError
from loosefit.geometry.vectors import unit
from loosefit.motion.rig import TargetRig

if TYPE_CHECKING:
    from loosefit.motion.joint_map import ResolvedMap


def parse_axis(text, path: Path | None = None) -> np.ndarray:
    """``"y"``, ``"+y"``, ``"-z"``... -> unit vector ``(3,)``."""
    t = str(text).strip().lower()
    sign = -1.0 if t.startswith("-") else 1.0
    t = t.lstrip("+-")
    if t not in ("x", "y", "z"):
        raise InputError(f"axis must be one of x, y, z with an optional sign, got {text!r}", path)
    v = np.zeros(3)
    v["xyz".index(t)] = sign
    return v


def _snap(v: np.ndarray, exclude: np.ndarray | None = None) -> np.ndarray:
    """The signed coordinate axis nearest to ``v``, optionally not along ``exclude``."""
    score = np.abs(v).copy()
    if exclude is not None:
        score[np.abs(exclude) > 0.5] = -1.0
    i = int(np.argmax(score))
    out = np.zeros(3)
    out[i] = np.sign(v[i]) or 1.0
    return out


def detect_axes(
    positions: np.ndarray,
    resolved: ResolvedMap,
    target: TargetRig,
    up: str | None = None,
    front: str | None = None,
    path: Path | None = None,
) -> np.ndarray:
    """The rotation ``A (3, 3)`` taking source world axes to loosefit's (Z up, character facing -Y).

    Up is the axis nearest the mean hip-to-head direction over all frames; front is the axis
    nearest the character's facing in the first frame (from the hips, and the shoulders when
    mapped), so the motion starts facing -Y to within 45 degrees and keeps the source's axis
    layout. ``up`` / ``front`` (``"y"``, ``"-z"``...) override the detection.

    Args:
        positions: ``(T, J, 3)`` source world joint positions in the file's axes.
    """
    roles = target.roles
    src = {target.joint_names[j]: s for j, s in resolved.source_of.items()}
    hips = positions[:, src[roles.legs[0][0]]] - positions[:, src[roles.legs[1][0]]]
    centre = 0.5 * (positions[:, src[roles.legs[0][0]]] + positions[:, src[roles.legs[1][0]]])
    top = [src[n] for n in roles.spine if n in src][-1]
    if up is None:
        rise = unit(positions[:, top] - centre).mean(0)
        up_v = _snap(rise)
    else:
        up_v = parse_axis(up, path)
    if front is None:
        left = unit(hips[0])
        if all(n in src for n in roles.arms):
            left = left + unit(positions[0, src[roles.arms[0]]] - positions[0, src[roles.arms[1]]])
        left = left - (left @ up_v) * up_v
        if np.linalg.norm(left) < 1e-6:
            raise InputError("cannot tell the source's facing direction: left-right axis is along up; "
                             "set 'front' in the joint map", path)
        left_v = _snap(left, exclude=up_v)
    else:
        front_v = parse_axis(front, path)
        if abs(front_v @ up_v) > 0.5:
            raise InputError(f"front axis {front!r} is along the up axis", path)
        left_v = np.cross(up_v, front_v)
    return np.stack([left_v, np.cross(up_v, left_v), up_v])
