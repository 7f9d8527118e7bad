"""Procedural motion library: unlimited distinct, smooth, plausible motions by seed.

``generate(kind, seconds, seed, body)`` returns a :class:`~loosefit.motion.Motion` on the body's
``cmu_mb`` rig. Every kind draws its parameters (speed, stride, amplitude, direction, turn rate,
tempo, ...) from the seed, so two seeds give two different motions, and the same seed always gives
the same one. Motions start at the origin facing -y; their root translation follows the gait (feet
stay planted while on the floor, flights are ballistic); every joint stays inside the limits of
:mod:`loosefit.motion.limits`; all curves are smooth from the first frame.

Kinds: ``walk``, ``run``, ``turn`` (stepping on the spot), ``spin`` (1-2 turns per second on one
foot, arms out), ``jump``, ``kick``, ``squat``, ``bow``, ``arm_raise``, ``wave``, ``sway`` (dance)
and ``mix`` (random kinds one after another, cross-faded over 0.3-0.6 s).
"""

from __future__ import annotations

import math
import numbers
import zlib
from dataclasses import fields

import numpy as np

from loosefit.errors import InputError
from loosefit.motion import actions, gaits
from loosefit.motion.curves import smoothstep
from loosefit.motion.kinematics import Performance, Skeleton, blend, solve, yaw_rotate
from loosefit.motion.motion import DEFAULT_FPS, Motion

_GENERATORS = {
    "walk": gaits.walk,
    "run": gaits.run,
    "turn": gaits.turn,
    "spin": gaits.spin,
    "jump": actions.jump,
    "kick": actions.kick,
    "squat": actions.squat,
    "bow": actions.bow,
    "arm_raise": actions.arm_raise,
    "wave": actions.wave,
    "sway": actions.sway,
}

#: Every kind :func:`generate` accepts.
KINDS: tuple[str, ...] = tuple(_GENERATORS) + ("mix",)

# Seconds each part of a mix lasts (before its cross-fade; at most 60% of the clip so that every
# mix has at least two parts), and the cross-fade length.
MIX_PART = (1.5, 4.0)
MIX_BLEND = (0.3, 0.6)


def _is_number(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x)


def _rng(kind: str, seed: int) -> np.random.Generator:
    # Each kind gets its own stream, so "walk" and "run" with one seed are unrelated draws.
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32(kind.encode())]))


def _mix(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> tuple[Performance, list[str]]:
    """Random kinds in sequence; each part is turned and moved to continue where the previous one
    is at the middle of their overlap, then the two are cross-faded over the overlap."""
    names = list(_GENERATORS)
    parts = []  # (first frame, kind, performance, frames shared with the next part)
    start = 0
    while start < T:
        kind = names[rng.integers(len(names))]
        if parts and kind == parts[-1][1]:
            kind = names[rng.integers(len(names))]
        overlap = max(2, int(round(rng.uniform(*MIX_BLEND) * fps)))
        n = min(int(round(rng.uniform(*MIX_PART) * fps)), int(np.ceil(0.6 * T))) + overlap
        perf = _GENERATORS[kind](np.random.default_rng(int(rng.integers(2**63))), skel, n, fps)
        parts.append((start, kind, perf, overlap))
        start += n - overlap
    out = _extend(parts[0][2], parts[-1][0] + parts[-1][2].num_frames)
    for (_, _, _, overlap), (start, _, perf, _) in zip(parts[:-1], parts[1:]):
        mid = overlap // 2
        turn = out.yaw[start + mid] - perf.yaw[mid]
        perf = perf.transformed(turn, out.root[start + mid, :2] - yaw_rotate(perf.root[mid, :2], turn))
        w = smoothstep((np.arange(perf.num_frames) + 0.5) / overlap)
        mixed = blend(out.slice(start, start + perf.num_frames), perf, w)
        for f in fields(Performance):
            getattr(out, f.name)[start : start + perf.num_frames] = getattr(mixed, f.name)
    return out.slice(0, T), [p[1] for p in parts]


def _extend(perf: Performance, n: int) -> Performance:
    """``perf`` extended to ``n`` frames by repeating its last frame."""
    idx = np.minimum(np.arange(n), perf.num_frames - 1)
    return Performance(**{f.name: getattr(perf, f.name)[idx] for f in fields(Performance)})


#: The longest motion :func:`generate` makes, seconds (an hour: 108,000 frames at 30 fps).
MAX_SECONDS = 3600.0
#: The frame rates :func:`generate` makes.
MIN_FPS, MAX_FPS = 1.0, 240.0


def generate(kind: str, seconds: float, seed: int, body, fps: float = DEFAULT_FPS) -> Motion:
    """A procedural motion.

    Args:
        kind: one of :data:`KINDS`.
        seconds: duration, at most :data:`MAX_SECONDS`; the motion has ``round(seconds * fps)`` frames (at least 2).
        seed: non-negative integer; the same ``(kind, seed, seconds, fps, body)`` always gives the
            same motion.
        body: a body on rig ``cmu_mb`` (e.g. :class:`~loosefit.body.AnnyBody`); its proportions set
            the stride, reach and heights.
        fps: frames per second, :data:`MIN_FPS` to :data:`MAX_FPS`.

    Returns:
        a :class:`~loosefit.motion.Motion` (``rotations (T, J, 3)`` float32 axis-angle, ``translation
        (T, 3)`` float32 metres) named ``"<kind>:seed=<seed>"`` (a mix appends its parts).
    """
    if kind not in KINDS:
        raise InputError(f"unknown procedural motion kind {kind!r}; choose one of {', '.join(KINDS)}")
    if not (_is_number(seconds) and seconds > 0):
        raise InputError(f"motion length must be a positive number of seconds, got {seconds!r}")
    if not (_is_number(fps) and fps > 0):
        raise InputError(f"fps must be a positive number, got {fps!r}")
    if seconds > MAX_SECONDS:
        raise InputError(f"motion length {seconds:g} s is longer than loosefit generates ({MAX_SECONDS:g} s: "
                         "loosefit.motion.procedural.MAX_SECONDS); generate pieces and simulate them one by one")
    if not MIN_FPS <= fps <= MAX_FPS:
        raise InputError(f"fps {fps:g} is outside the frame rates loosefit generates ({MIN_FPS:g} to {MAX_FPS:g}: "
                         "loosefit.motion.procedural.MIN_FPS / MAX_FPS)")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    skel = Skeleton.from_body(body)
    T = max(2, int(round(seconds * fps)))
    rng = _rng(kind, int(seed))
    name = f"{kind}:seed={int(seed)}"
    if kind == "mix":
        perf, parts = _mix(rng, skel, T, fps)
        name += ":" + "+".join(parts)
    else:
        perf = _GENERATORS[kind](rng, skel, T, fps)
    # Start at the origin facing -y.
    perf = perf.transformed(-perf.yaw[0], -yaw_rotate(perf.root[0, :2], -perf.yaw[0]))
    rotations, translation = solve(perf, skel)
    return Motion(rotations, translation, float(fps), body.rig, body.joint_names, name)
