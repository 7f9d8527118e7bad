"""Foot placement: stance phases, swing trajectories and the pelvis height the legs can reach.

A foot is tracked by its toe joint. While planted, the toe stays put: the foot lies flat, then
rolls onto its toes by lifting the heel (pivoting about the toe joint) before it leaves the floor;
a planted foot may also pivot its heading on the ball of the foot (turns, spins). In the air the toe
follows a smooth arc from one placement to the next. Because the toe joint never goes below its
flat-foot height and the ankle is computed from the toe, no foot joint sinks into the floor.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.ndimage import gaussian_filter1d, minimum_filter1d

from loosefit.motion.curves import smoothstep
from loosefit.motion.kinematics import SIDE_SIGN, Skeleton, root_height_limit, rot_x, rot_z, yaw_rotate

# A toe less than this above its flat height counts as planted.
GROUND_TOLERANCE = 1e-3


@dataclass
class Stance:
    """One foot contact.

    Attributes:
        t_on, t_off: touch-down and lift-off times, seconds.
        toe: ``(2,)`` toe joint position on the floor, metres.
        yaw: foot heading at time ``t_ref``, radians.
        t_ref: reference time of ``yaw`` (mid-stance).
        pivot: fraction of the body's heading change the planted foot follows (0 fixed, 1 pivots with the body).
        heel: heel lift (foot pitch, radians) reached at lift-off.
        heel_time: seconds the heel takes to rise before lift-off.
        land: heel lift at touch-down (a forefoot landing), lowered over ``land_time`` seconds.
        land_time: seconds the heel takes to come down after touch-down.
    """

    t_on: float
    t_off: float
    toe: np.ndarray
    yaw: float
    t_ref: float
    pivot: float = 0.0
    heel: float = 0.0
    heel_time: float = 0.0
    land: float = 0.0
    land_time: float = 0.0


def placement(
    skel: Skeleton, side: int, xy, yaw: float, width=0.0, forward=0.0, toe_out=0.0
) -> tuple[np.ndarray, float]:
    """Toe position ``(2,)`` and heading of foot ``side`` placed in its rest spot under a pelvis at
    ``xy`` heading ``yaw``; ``width`` moves it outward, ``forward`` forward, ``toe_out`` turns it outward (radians)."""
    offset = (skel.ankle[side] - skel.root)[:2] + np.array([SIDE_SIGN[side] * width, -forward])
    ankle = np.asarray(xy, dtype=np.float64) + yaw_rotate(offset, yaw)
    foot_yaw = yaw + SIDE_SIGN[side] * toe_out
    return ankle + yaw_rotate((skel.toe[side] - skel.ankle[side])[:2], foot_yaw), foot_yaw


def ankle_from_toe(skel: Skeleton, side: int, toe: np.ndarray, yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Ankle positions ``(T, 3)`` for the toe joint at ``toe (T, 3)`` and the foot at ``yaw``, ``pitch (T,)``."""
    offset = skel.ankle[side] - skel.toe[side]
    return toe + np.einsum("tab,b->ta", rot_z(yaw) @ rot_x(pitch), offset)


def swing_bump(s: np.ndarray, skew: float = 0.0) -> np.ndarray:
    """Lift profile over a swing, ``s`` in ``[0, 1]``: 0 at both ends with zero slope, peak 1;
    ``skew > 0`` moves the peak earlier (a running heel kick)."""
    a, b = 2.0, 2.0 + skew
    peak = (a / (a + b)) ** a * (b / (a + b)) ** b
    s = np.clip(s, 0.0, 1.0)
    return s**a * (1 - s) ** b / peak


def foot_track(
    t: np.ndarray,
    stances: list[Stance],
    skel: Skeleton,
    side: int,
    body_yaw: Callable[[np.ndarray], np.ndarray],
    lift: float,
    skew: float = 0.0,
    free_swing: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Toe ``(T, 3)``, foot yaw ``(T,)``, pitch ``(T,)`` and free weight ``(T,)`` of one foot
    stepping through ``stances`` (sorted, disjoint, covering ``t``), with swings lifting the toe by
    ``lift`` metres. Mid-swing the foot is free by ``free_swing`` (1: oriented relative to the shank,
    see :class:`~loosefit.motion.kinematics.Performance`; only for swings high enough that the toe
    cannot scuff the floor); it is placed by yaw and pitch near the floor.
    ``body_yaw(t)`` is the pelvis heading, used by pivoting stances."""
    h = skel.toe_height
    toe = np.zeros((len(t), 3))
    yaw = np.zeros(len(t))
    pitch = np.zeros(len(t))
    free = np.zeros(len(t))

    def stance_yaw(st: Stance, time):
        return st.yaw + st.pivot * (body_yaw(np.asarray(time, dtype=np.float64)) - body_yaw(np.array(st.t_ref)))

    for k, st in enumerate(stances):
        m = (t >= st.t_on) & (t <= st.t_off)
        if k == 0:
            m |= t < st.t_on
        if k == len(stances) - 1:
            m |= t > st.t_off
        toe[m] = [st.toe[0], st.toe[1], h]
        yaw[m] = stance_yaw(st, t[m])
        if st.heel_time > 0:
            pitch[m] += st.heel * smoothstep((t[m] - (st.t_off - st.heel_time)) / st.heel_time)
        if st.land_time > 0:
            pitch[m] += st.land * (1 - smoothstep((t[m] - st.t_on) / st.land_time))
        if k + 1 < len(stances):
            nxt = stances[k + 1]
            m = (t > st.t_off) & (t < nxt.t_on)
            s = (t[m] - st.t_off) / (nxt.t_on - st.t_off)
            w = smoothstep(s)[:, None]
            toe[m, :2] = (1 - w) * st.toe + w * nxt.toe
            toe[m, 2] = h + lift * swing_bump(s, skew)
            y0, y1 = stance_yaw(st, st.t_off), stance_yaw(nxt, nxt.t_on)
            yaw[m] = (1 - w[:, 0]) * y0 + w[:, 0] * y1
            pitch[m] = st.heel * (1 - smoothstep(s / 0.6)) + nxt.land * smoothstep((s - 0.4) / 0.6)
            free[m] = free_swing * smoothstep(s / 0.3) * (1 - smoothstep((s - 0.7) / 0.3))
    return toe, yaw, pitch, free


def alternating(t0: float, t1: float, period: float, duty: float, phase: float) -> list[list[tuple[float, float]]]:
    """Stance intervals ``[(t_on, t_off), ...]`` per foot for a gait of cycle ``period`` seconds
    where each foot is down for ``duty`` of the cycle; the left foot lands at ``phase + k period``,
    the right half a cycle later. Covers ``[t0, t1]`` with one spare cycle on each side."""
    out = []
    for offset in (0.0, 0.5 * period):
        start = phase + offset + np.floor((t0 - phase - offset) / period - 1) * period
        times = np.arange(start, t1 + 2 * period, period)
        out.append([(float(a), float(a + duty * period)) for a in times])
    return out


def settle_height(
    skel: Skeleton,
    fps: float,
    root_xy: np.ndarray,
    yaw: np.ndarray,
    pitch: np.ndarray,
    roll: np.ndarray,
    ankle: np.ndarray,
    planted: np.ndarray,
    nominal: np.ndarray,
    reach: float = 0.99,
) -> np.ndarray:
    """Root height ``(T,)``: ``nominal (T,)`` lowered wherever a planted foot (``planted (T, 2)``
    bool) could not reach its ankle target ``(T, 2, 3)`` with ``reach`` of its leg, then smoothed
    (dips are widened before smoothing so the result stays under the limit)."""
    limit = root_height_limit(skel, root_xy, yaw, pitch, roll, ankle, reach)
    h = np.minimum(nominal, np.where(planted, limit, np.inf).min(1))
    size = max(1, int(round(0.12 * fps))) | 1
    h = minimum_filter1d(h, size, mode="nearest")
    return gaussian_filter1d(h, 0.04 * fps, mode="nearest")
