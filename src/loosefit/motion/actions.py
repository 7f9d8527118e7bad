"""Motions performed on the spot: jump, kick, squat, bow, arm raise, wave, swaying dance.

Each generator returns a :class:`~loosefit.motion.kinematics.Performance` starting at the origin
facing -y. Planted feet stay where they are; a foot leaving the floor first lifts its heel, and
blends from its planted spot into its path through the air and back (see :func:`_air_blend`).
"""

from __future__ import annotations

import numpy as np

from loosefit.motion.curves import hermite, keyframes, ramp, smooth_noise, smoothstep, window
from loosefit.motion.footsteps import ankle_from_toe, placement, settle_height, swing_bump
from loosefit.motion.kinematics import (
    SIDE_SIGN,
    Performance,
    Skeleton,
    pelvis_rotation,
    root_height_limit,
    rot_x,
    rot_z,
    yaw_rotate,
)
from loosefit.motion.posture import Posture

GRAVITY = 9.81
_DEG = np.pi / 180.0


def _planted(skel: Skeleton, width: float, toe_out: float, xy=(0.0, 0.0), yaw: float = 0.0):
    """Toe positions ``(2, 2)`` and headings ``(2,)`` of both feet placed under a pelvis at ``xy``, ``yaw``."""
    spots = [placement(skel, side, np.asarray(xy, dtype=np.float64), yaw, width, 0.0, toe_out) for side in (0, 1)]
    return np.stack([p for p, _ in spots]), np.array([y for _, y in spots])


def _flat_ankles(skel: Skeleton, T: int, toes: np.ndarray, yaws: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Ankles ``(T, 2, 3)`` of feet with toes at ``toes (2, 2)``, headings ``yaws (2,)``, heel lift ``pitch (T, 2)``."""
    out = np.zeros((T, 2, 3))
    for side in (0, 1):
        toe = np.concatenate([np.broadcast_to(toes[side], (T, 2)), np.full((T, 1), skel.toe_height)], -1)
        out[:, side] = ankle_from_toe(skel, side, toe, np.full(T, yaws[side]), pitch[:, side])
    return out


def _air_blend(t, lift_off: float, touch_down: float, fade: float = 0.12) -> np.ndarray:
    """Weight ``(T,)`` of a foot's airborne path: 0 on the floor, rising over ``fade`` seconds after
    ``lift_off`` and falling to 0 at ``touch_down``; zero velocity at both contacts."""
    return ramp(t, lift_off, fade) * (1 - ramp(t, touch_down - fade, fade))


def _standing(rng, skel: Skeleton, T: int, fps: float, post: Posture, sway: float = 0.015, width=None):
    """Common base for motions with both feet planted: adds idle motion to ``post`` and returns the
    time axis ``(T,)``, the feet (toes ``(2, 2)``, headings ``(2,)``) and a root slowly shifting
    its weight by about ``sway`` metres, ``(T, 2)``."""
    t = np.arange(T) / fps
    width = rng.uniform(0.0, 0.08) if width is None else width
    toes, yaws = _planted(skel, width, rng.uniform(0, 15) * _DEG)
    root_xy = np.stack([smooth_noise(rng, t, 2.5, sway), smooth_noise(rng, t, 3.0, 0.5 * sway)], -1)
    post.idle(rng, t, 1.0)
    return t, toes, yaws, root_xy


def _perf(skel, fps, root_xy, height, yaw, pitch, roll, ankle, fyaw, fpitch, free, flex, post):
    """Assemble a Performance, lowering the root where the feet on the floor (``free == 0``) could
    not be reached with straight knees."""
    height = settle_height(skel, fps, root_xy, yaw, pitch, roll, ankle, free == 0, height, reach=1.0)
    root = np.concatenate([root_xy, np.asarray(height)[:, None]], -1)
    return Performance(root, yaw, pitch, roll, ankle, fyaw, fpitch, free, flex, post.params)


def _on_both_feet(skel, fps, toes, yaws, root_xy, height, yaw, pitch, roll, post) -> Performance:
    """A Performance with both feet flat at ``toes (2, 2)``, ``yaws (2,)``; ``height``, ``yaw``,
    ``pitch`` and ``roll`` are scalars or ``(T,)``."""
    T = len(root_xy)
    zero = np.zeros((T, 2))
    ankle = _flat_ankles(skel, T, toes, yaws, zero)
    height, yaw, pitch, roll = (np.broadcast_to(np.asarray(v, dtype=np.float64), (T,)).copy()
                                for v in (height, yaw, pitch, roll))
    fyaw = np.broadcast_to(yaws, (T, 2)).copy()
    return _perf(skel, fps, root_xy, height, yaw, pitch, roll, ankle, fyaw, zero, zero, zero, post)


def _repeated(rng, t: np.ndarray, down, hold, up, pause, depth=(0.6, 1.0)) -> np.ndarray:
    """``(T,)`` profile of a movement repeated back to back: from 0 down to a depth drawn from
    ``depth`` in ``down`` seconds, held for ``hold``, back up in ``up``, rest for ``pause`` (each a
    ``(lo, hi)`` range drawn per repetition). The first repetition may start before the clip."""
    times, values = [], []
    cursor = -rng.uniform(0.0, 2.0)
    while cursor < t[-1] + 1e-9:
        d_down, d_hold, d_up, d_pause = (rng.uniform(*r) for r in (down, hold, up, pause))
        d = rng.uniform(*depth)
        times += [cursor, cursor + d_down, cursor + d_down + d_hold, cursor + d_down + d_hold + d_up]
        values += [0.0, d, d, 0.0]
        cursor += d_down + d_hold + d_up + d_pause
    return keyframes(t, times, values)


def squat(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Repeated squats: feet apart and turned out, hips back, chest forward, arms forward for balance
    (or hands on the hips), 1.6-3.2 s per repetition, varying depth."""
    post = Posture(skel, T)
    t, toes, yaws, root_xy = _standing(rng, skel, T, fps, post, 0.01, rng.uniform(0.04, 0.14))
    depth = rng.uniform(0.12, 0.32)
    d = _repeated(rng, t, down=(0.6, 1.2), hold=(0.05, 0.5), up=(0.6, 1.2), pause=(0.05, 0.6))
    drop = depth * d
    root_xy = root_xy + np.stack([np.zeros(T), 0.55 * drop], -1)  # hips go back
    lean = rng.uniform(0.6, 1.0) * 90 * _DEG * drop
    post.spine(bend=0.3 * lean)
    post.head(nod=-0.3 * lean)
    if rng.random() < 0.7:
        reach = rng.uniform(60, 90) * _DEG
        for side in (0, 1):
            post.arm(side, flex=reach * (0.3 + 0.7 * d), abduct=rng.uniform(10, 25) * _DEG,
                     elbow=(1 - d) * 40 * _DEG + 10 * _DEG)
    else:
        for side in (0, 1):
            post.arm(side, flex=-10 * _DEG, abduct=45 * _DEG, elbow=100 * _DEG, twist=30 * _DEG)
    return _on_both_feet(skel, fps, toes, yaws, root_xy, skel.root[2] - 0.01 - drop, 0.0, lean, 0.0, post)


def bow(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Repeated bows from the hips (25-70 degrees) with the head dropping, held briefly; arms hang,
    stay at the sides, or one hand on the chest with the other behind the back."""
    post = Posture(skel, T)
    t, toes, yaws, root_xy = _standing(rng, skel, T, fps, post, 0.01)
    d = _repeated(rng, t, down=(0.5, 1.0), hold=(0.3, 1.2), up=(0.6, 1.2), pause=(0.3, 1.2), depth=(0.5, 1.0))
    hips = rng.uniform(25, 70) * _DEG * d
    back = rng.uniform(5, 25) * _DEG * d
    post.spine(bend=back)
    post.head(nod=rng.uniform(10, 30) * _DEG * d)
    root_xy = root_xy + np.stack([np.zeros(T), 0.12 * np.sin(hips)], -1)  # hips back to keep balance
    style = rng.choice(["hang", "sides", "chest"])
    for side in (0, 1):
        if style == "hang":  # arms keep hanging under gravity as the trunk tips
            post.arm(side, flex=0.9 * (hips + back), abduct=10 * _DEG, elbow=15 * _DEG)
        elif style == "sides":
            post.arm(side, flex=0.1 * hips, abduct=8 * _DEG, elbow=10 * _DEG)
    if style == "chest":
        hand = int(rng.integers(2))
        post.arm(hand, flex=45 * _DEG, abduct=20 * _DEG, elbow=120 * _DEG, twist=40 * _DEG)
        post.arm(1 - hand, flex=-25 * _DEG, abduct=20 * _DEG, elbow=80 * _DEG, twist=-40 * _DEG)
    return _on_both_feet(skel, fps, toes, yaws, root_xy, skel.root[2] - 0.01 - 0.03 * d, 0.0, hips, 0.0, post)


_ARM_POSES = {  # (flex, abduct, elbow) in degrees: ranges of a named arm pose
    "down": ((-5, 15), (8, 20), (10, 40)),
    "side": ((-5, 20), (75, 100), (0, 30)),
    "front": ((70, 100), (10, 30), (0, 30)),
    "up": ((0, 30), (145, 170), (5, 30)),
    "forward_up": ((120, 150), (15, 35), (5, 30)),
    "head": ((10, 40), (100, 125), (110, 135)),
    "hips": ((-15, 0), (40, 50), (90, 110)),
}


def arm_raise(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Arm raises through a random sequence of poses (down, sideways, forward, overhead, hands on the
    head or hips), both arms together or each its own, 0.8-1.8 s per move, weight shifting."""
    post = Posture(skel, T)
    t, toes, yaws, root_xy = _standing(rng, skel, T, fps, post, 0.02)
    names = list(_ARM_POSES)
    times = np.arange(-rng.uniform(0, 1.5), T / fps + 2.0, rng.uniform(0.8, 1.8))
    keys = np.zeros((len(times), 2, 3))
    for k in range(len(times)):
        pose = names[rng.integers(len(names))]
        for side in (0, 1):
            if side == 1 and rng.random() < 0.5:
                pose = names[rng.integers(len(names))]
            keys[k, side] = [rng.uniform(*r) * _DEG for r in _ARM_POSES[pose]]
    arms = keyframes(t, times, keys)
    for side in (0, 1):
        post.arm(side, flex=arms[:, side, 0], abduct=arms[:, side, 1], elbow=arms[:, side, 2])
    # The chest follows the arms a little: back arches when both go up.
    up = np.clip((arms[:, :, 1] + arms[:, :, 0]).mean(1) / np.pi - 0.5, 0.0, 1.0)
    post.spine(bend=-8 * _DEG * up, side=4 * _DEG * (arms[:, 1, 1] - arms[:, 0, 1]) / np.pi)
    yaw = smooth_noise(rng, t, 3.0, 4 * _DEG)
    return _on_both_feet(skel, fps, toes, yaws, root_xy, skel.root[2] - 0.01, yaw, 0.0, 0.0, post)


def wave(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Waving: an arm (sometimes both) goes up, the forearm swings side to side at 1.5-3 Hz for a
    while, the arm comes down; the body leans slightly away and the head tilts."""
    post = Posture(skel, T)
    t, toes, yaws, root_xy = _standing(rng, skel, T, fps, post, 0.015)
    arms = np.zeros((T, 2, 4))  # flex, abduct, elbow, swing weight
    rest = np.array([0.0, 12 * _DEG, 20 * _DEG])
    arms[:, :, :3] = rest
    cursor = -rng.uniform(0.0, 2.0)
    lean = np.zeros(T)
    while cursor < T / fps:
        up, hold = rng.uniform(0.4, 0.8), rng.uniform(1.2, 3.5)
        down, pause = rng.uniform(0.4, 0.8), rng.uniform(0.3, 1.5)
        both = rng.random() < 0.25
        side = int(rng.integers(2))
        pose = np.array([rng.uniform(0, 30), rng.uniform(100, 150), rng.uniform(50, 100)]) * _DEG
        w = window(t, cursor, cursor + up + hold + down, up)
        for s in ((0, 1) if both else (side,)):
            arms[:, s, :3] += w[:, None] * (pose - rest)
            waving = window(t, cursor + 0.6 * up, cursor + up + hold + 0.4 * down, 0.3)
            arms[:, s, 3] = np.maximum(arms[:, s, 3], waving)
        if not both:
            lean += -SIDE_SIGN[side] * rng.uniform(2, 6) * _DEG * w
        cursor += up + hold + down + pause
    freq = rng.uniform(1.5, 3.0)
    amp = rng.uniform(15, 30) * _DEG
    wag = np.sin(2 * np.pi * freq * t)
    for side in (0, 1):
        swing = arms[:, side, 3] * amp * wag * SIDE_SIGN[side]
        post.arm(side, flex=arms[:, side, 0], abduct=arms[:, side, 1], elbow=arms[:, side, 2], twist=swing,
                 wrist=0.5 * swing)
    post.spine(side=lean)
    post.head(tilt=-0.8 * lean)
    yaw = smooth_noise(rng, t, 3.0, 5 * _DEG)
    return _on_both_feet(skel, fps, toes, yaws, root_xy, skel.root[2] - 0.01, yaw, 0.0, 0.5 * lean, post)


def sway(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Swaying dance to a beat of 80-130 bpm: hips shift side to side over alternating bent knees,
    pelvis rolls and twists, the chest counters, arms move in rhythm, the head bobs."""
    post = Posture(skel, T)
    t, toes, yaws, root_xy = _standing(rng, skel, T, fps, post, 0.01, rng.uniform(0.06, 0.16))
    beat = 60.0 / rng.uniform(80, 130)
    phase = 2 * np.pi * rng.random()
    cycle = np.pi * t / beat + phase  # a full side-to-side cycle takes two beats
    amp = rng.uniform(0.03, 0.08) * (1 + 0.3 * smooth_noise(rng, t, 4.0, 1.0))
    shift = amp * np.sin(cycle)
    root_xy = root_xy + np.stack([shift, np.zeros(T)], -1)
    bob = rng.uniform(0.01, 0.035) * (0.5 + 0.5 * np.cos(2 * cycle))  # dips on every beat
    roll = -rng.uniform(4, 10) * _DEG * np.sin(cycle)  # the hip over the standing leg rises
    twist = rng.uniform(5, 20) * _DEG * np.sin(cycle + rng.uniform(0, np.pi))
    yaw = twist + smooth_noise(rng, t, 4.0, 8 * _DEG)
    post.spine(side=-1.3 * roll, twist=-0.6 * twist, bend=rng.uniform(0, 10) * _DEG)
    post.head(tilt=0.4 * roll, nod=4 * _DEG * np.cos(2 * cycle))
    abduct = rng.uniform(20, 45) * _DEG
    elbow = rng.uniform(50, 100) * _DEG
    arm_amp = rng.uniform(10, 30) * _DEG
    for side in (0, 1):
        pump = arm_amp * np.sin(cycle + SIDE_SIGN[side] * np.pi / 2)
        post.arm(side, flex=rng.uniform(10, 40) * _DEG + pump, abduct=abduct + 0.5 * pump, elbow=elbow - 0.5 * pump)
    lean = rng.uniform(0, 5) * _DEG
    return _on_both_feet(skel, fps, toes, yaws, root_xy, skel.root[2] - 0.02 - bob, yaw, lean, roll, post)


def _leg_path(skel, side: int, direction: np.ndarray, alpha: float, chamber: float, knee: float) -> tuple:
    """Ankle offsets from the hip ``(3,)`` (yaw frame) of a kick toward horizontal ``direction (2,)``:
    chamber (thigh at ``chamber`` radians from vertical toward ``direction``, knee folded by
    ``knee``) and extension (leg nearly straight at ``alpha`` from vertical)."""
    thigh_len = np.linalg.norm(skel.knee[side] - skel.hip[side])
    shin_len = np.linalg.norm(skel.ankle[side] - skel.knee[side])
    down = np.array([0.0, 0.0, -1.0])
    horiz = np.array([direction[0], direction[1], 0.0])
    thigh = np.cos(chamber) * down + np.sin(chamber) * horiz
    shin = rot_x(knee) @ thigh  # the knee folds the shin backward about the body's left-right axis
    chamber_at = thigh_len * thigh + shin_len * shin
    extend_at = 0.93 * skel.max_reach(side) * (np.cos(alpha) * down + np.sin(alpha) * horiz)
    return chamber_at, extend_at


def kick(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Kicks: shift the weight onto one foot, chamber the knee, snap the leg out (front, side or back),
    re-chamber, put the foot down, recover; the trunk leans against the kick, arms guard or balance."""
    post = Posture(skel, T)
    t = np.arange(T) / fps
    width = rng.uniform(0.02, 0.1)
    toes, yaws = _planted(skel, width, rng.uniform(0, 15) * _DEG)
    rest_ankles = _flat_ankles(skel, 1, toes, yaws, np.zeros((1, 2)))[0]
    ankle = np.zeros((T, 2, 3))
    fyaw = np.broadcast_to(yaws, (T, 2)).copy()
    fpitch, free, flex = np.zeros((T, 2)), np.zeros((T, 2)), np.zeros((T, 2))
    shift, pitch, roll, yaw = np.zeros(T), np.zeros(T), np.zeros(T), np.zeros(T)
    air_keys = []
    leg = int(rng.integers(2))
    cursor = -rng.uniform(0.0, 1.5)
    while cursor < T / fps:
        kind = rng.choice(["front", "side", "back"], p=[0.55, 0.3, 0.15])
        shift_t, chamber_t = rng.uniform(0.3, 0.5), rng.uniform(0.2, 0.3)
        extend_t, hold_t = rng.uniform(0.13, 0.2), rng.uniform(0.0, 0.2)
        retract_t, down_t, recover_t = rng.uniform(0.18, 0.25), rng.uniform(0.25, 0.35), rng.uniform(0.3, 0.6)
        k0 = cursor + shift_t  # lift-off
        k1, k2 = k0 + chamber_t, k0 + chamber_t + extend_t
        k3, k4 = k2 + hold_t, k2 + hold_t + retract_t
        k5 = k4 + down_t  # touch-down
        active = window(t, k0 - 0.1, k5, 0.25)
        s = SIDE_SIGN[leg]
        if kind == "front":
            direction, alpha = np.array([0.0, -1.0]), rng.uniform(45, 100) * _DEG
            chamber, knee = min(alpha + 10 * _DEG, 110 * _DEG), 115 * _DEG
            pitch += -rng.uniform(5, 15) * _DEG * active
            foot = rng.uniform(-15, 40) * _DEG
        elif kind == "side":
            lean = rng.uniform(5, 25) * _DEG
            direction, alpha = np.array([s, 0.0]), rng.uniform(30, 45) * _DEG + lean
            chamber, knee = alpha, 100 * _DEG
            roll += -s * lean * active
            foot = rng.uniform(-15, 10) * _DEG
        else:
            lean = rng.uniform(15, 35) * _DEG
            direction, alpha = np.array([0.0, 1.0]), rng.uniform(20, 30) * _DEG + lean
            chamber, knee = -40 * _DEG, 110 * _DEG
            pitch += lean * active
            foot = rng.uniform(-15, 0) * _DEG
        chamber_at, extend_at = _leg_path(skel, leg, direction, alpha, chamber, knee)
        shift += ramp(t, cursor, shift_t) * (1 - ramp(t, k5, recover_t))
        air_keys.append((leg, k0, k5, [k0, k1, k2, k3, k4, k5], chamber_at, extend_at))
        heel = 25 * _DEG * ramp(t, k0 - 0.15, 0.15) * (1 - ramp(t, k5, 0.15))
        fpitch[:, leg] += heel
        w = _air_blend(t, k0, k5, 0.15)
        free[:, leg] = np.maximum(free[:, leg], smoothstep((w - 0.3) / 0.7))
        flex[:, leg] += foot * w
        cursor = k5 + recover_t + rng.uniform(0.1, 0.6)
        leg = 1 - leg if rng.random() < 0.6 else leg

    # The pelvis moves over the standing foot, more so while the other leg is up.
    lateral = np.zeros(T)
    for leg_k, k0, k5, *_ in air_keys:
        lateral += -SIDE_SIGN[leg_k] * 0.09 * ramp(t, k0 - 0.4, 0.35) * (1 - ramp(t, k5, 0.4))
    drift = np.stack([smooth_noise(rng, t, 3.0, 0.01), smooth_noise(rng, t, 3.0, 0.01)], -1)
    root_xy = np.stack([lateral, np.zeros(T)], -1) + drift
    height = np.full(T, skel.root[2] - rng.uniform(0.01, 0.04))
    W = pelvis_rotation(yaw, pitch, roll)
    for side in (0, 1):  # planted feet, heels lifting around each kick
        toe = np.concatenate([np.broadcast_to(toes[side], (T, 2)), np.full((T, 1), skel.toe_height)], -1)
        ankle[:, side] = ankle_from_toe(skel, side, toe, fyaw[:, side], fpitch[:, side])
    root = np.concatenate([root_xy, height[:, None]], -1)
    for leg_k, k0, k5, times, chamber_at, extend_at in air_keys:
        hip = root + W @ skel.hip_offsets()[leg_k]
        start = rest_ankles[leg_k] - (skel.root + skel.hip_offsets()[leg_k])
        offsets = keyframes(t, times, np.stack([start, chamber_at, extend_at, extend_at, chamber_at, start]))
        w = _air_blend(t, k0, k5, 0.15)[:, None]
        inside = (t >= k0) & (t <= k5)
        ankle[inside, leg_k] = ((1 - w) * ankle[:, leg_k] + w * (hip + offsets))[inside]
    guard = rng.random() < 0.6
    for side in (0, 1):
        if guard:
            post.arm(side, flex=rng.uniform(35, 60) * _DEG, abduct=rng.uniform(15, 25) * _DEG,
                     elbow=rng.uniform(100, 130) * _DEG)
        else:
            post.arm(side, flex=10 * _DEG, abduct=(15 + 45 * shift) * _DEG, elbow=30 * _DEG)
    post.spine(bend=-0.5 * pitch, side=-0.5 * roll)
    post.idle(rng, t, 0.7)
    return _perf(skel, fps, root_xy, height, yaw, pitch, roll, ankle, fyaw, fpitch, free, flex, post)


def jump(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Jumps: crouch with the arms swinging back, push off onto the toes with the arms swinging up,
    fly on a ballistic arc (0.06-0.35 m high, sometimes forward and turning up to a full turn), land
    on the toes, absorb and stand up."""
    t = np.arange(T) / fps
    post = Posture(skel, T)
    width, toe_out = rng.uniform(0.0, 0.08), rng.uniform(0, 12) * _DEG
    stand_z = skel.root[2] - 0.005
    reach = 0.98 * min(skel.max_reach(0), skel.max_reach(1))  # knees not locked at take-off

    def straight_z(toes, yaws, heel, xy, heading):  # root height with nearly straight legs, feet on their toes
        feet = _flat_ankles(skel, 1, toes, yaws, np.full((1, 2), heel))
        one = np.zeros(1)
        return root_height_limit(skel, xy[None], one + heading, one, one, feet, 0.98).min()

    height, root_xy, yaw = np.full(T, stand_z), np.zeros((T, 2)), np.zeros(T)
    ankle = np.zeros((T, 2, 3))
    fyaw, fpitch, free, flex = (np.zeros((T, 2)) for _ in range(4))
    arm_flex, bend = np.full(T, 5 * _DEG), np.zeros(T)
    center, heading = np.zeros(2), 0.0
    cursor = -rng.uniform(0.0, 1.5)
    while cursor < T / fps:
        crouch_t, push_t = rng.uniform(0.3, 0.5), rng.uniform(0.2, 0.3)
        flight = 2 * np.sqrt(2 * GRAVITY * rng.uniform(0.06, 0.35)) / GRAVITY
        absorb_t, stand_t, rest_t = rng.uniform(0.25, 0.4), rng.uniform(0.3, 0.6), rng.uniform(0.2, 1.0)
        turns = [0.0, 0.0, 0.5 * np.pi, np.pi] + ([2 * np.pi] if flight > 0.45 else [])
        turn = rng.choice(turns) * rng.choice([-1.0, 1.0])
        forward = rng.choice([0.0, rng.uniform(0.1, 0.6)])
        c_depth, a_depth = rng.uniform(0.1, 0.22), rng.uniform(0.08, 0.18)
        heel_off, heel_land = rng.uniform(30, 45) * _DEG, rng.uniform(15, 30) * _DEG
        tuck = rng.uniform(0.0, 0.2)
        t0 = cursor
        t_low, t_off = t0 + crouch_t, t0 + crouch_t + push_t
        t_land = t_off + flight
        t_absorb, t_stand = t_land + absorb_t, t_land + absorb_t + stand_t
        end = t_stand + rest_t
        land_center = center + yaw_rotate(np.array([0.0, -forward]), heading)
        vh = (land_center - center) / flight
        toes0, yaws0 = _planted(skel, width, toe_out, center, heading)
        toes1, yaws1 = _planted(skel, width, toe_out, land_center, heading + turn)
        z_off = straight_z(toes0, yaws0, heel_off, center, heading)
        z_land = straight_z(toes1, yaws1, heel_land, land_center, heading + turn)
        v_up = 0.5 * GRAVITY * flight + (z_land - z_off) / flight  # lands at z_land after ``flight`` seconds
        v_down = v_up - GRAVITY * flight
        seg = (t >= t0) & (t < end)
        ts = t[seg]
        n = len(ts)
        tau = ts - t_off
        # Vertical: crouch, push up to take-off speed, ballistic flight, absorb the landing, stand.
        height[seg] = np.where(ts < t_low, hermite(ts, t0, t_low, stand_z, stand_z - c_depth, 0, 0),
                      np.where(ts < t_off, hermite(ts, t_low, t_off, stand_z - c_depth, z_off, 0, v_up),
                      np.where(ts < t_land, z_off + v_up * tau - 0.5 * GRAVITY * tau * tau,
                      np.where(ts < t_absorb, hermite(ts, t_land, t_absorb, z_land, stand_z - a_depth, v_down, 0),
                               hermite(ts, t_absorb, t_stand, stand_z - a_depth, stand_z, 0, 0)))))
        # Horizontal: hips back in the crouch, forward through the flight, back on landing.
        back0 = center + yaw_rotate(np.array([0.0, 0.5 * c_depth]), heading)
        back1 = land_center + yaw_rotate(np.array([0.0, 0.5 * a_depth]), heading + turn)
        zero2 = np.zeros(2)
        before_low, before_off, before_land, before_abs = ((ts < x)[:, None] for x in (t_low, t_off, t_land, t_absorb))
        root_xy[seg] = np.where(before_low, hermite(ts, t0, t_low, center, back0, zero2, zero2),
                       np.where(before_off, hermite(ts, t_low, t_off, back0, center, zero2, vh),
                       np.where(before_land, center + vh * tau[:, None],
                       np.where(before_abs, hermite(ts, t_land, t_absorb, land_center, back1, vh, zero2),
                                hermite(ts, t_absorb, t_stand, back1, land_center, zero2, zero2)))))
        turning = (t_off - 0.5 * push_t, flight + 0.5 * push_t + 0.5 * absorb_t)  # start, duration
        spin_of = lambda x: turn * smoothstep((x - turning[0]) / turning[1])  # noqa: E731
        spin = spin_of(ts)
        yaw[seg] = heading + spin
        # Feet: heels rise in the push and the planted feet pivot on their balls with the body's
        # turn; in the air they move with the hips, from their take-off spot to under the hips
        # (knees tucked mid-flight) to their landing spot; heels come down after landing.
        s_fl = np.clip(tau / flight, 0.0, 1.0)
        leave, arrive = smoothstep(s_fl / 0.35), smoothstep((s_fl - 0.65) / 0.35)
        flying = (ts > t_off) & (ts < t_land)
        W = pelvis_rotation(yaw[seg], np.zeros(n), np.zeros(n))
        for side in (0, 1):
            def ground(x, side=side):
                early = x < 0.5 * (t_off + t_land)
                toe = np.where(early[:, None], toes0[side], toes1[side])
                toe = np.concatenate([toe, np.full((len(x), 1), skel.toe_height)], -1)
                fy = np.where(early, yaws0[side], yaws1[side] - turn) + spin_of(x)
                rising, lowering = ramp(x, t_low, push_t), 1 - ramp(x, t_land, 0.6 * absorb_t)
                fp = np.where(early, heel_off * rising, heel_land * lowering)
                return ankle_from_toe(skel, side, toe, fy, fp), fy, fp

            def relative(x, xy, z, side=side):  # ankle relative to the hip, in the body's heading frame
                yaw_x = heading + spin_of(np.array([x]))[0]
                hip = np.append(xy, z) + rot_z(yaw_x) @ skel.hip_offsets()[side]
                d = ground(np.array([x]))[0][0] - hip
                return np.append(yaw_rotate(d[:2], -yaw_x), d[2])

            on_floor, fy, fp = ground(ts)
            tucked = np.stack([np.zeros(n), np.zeros(n), -(reach - tuck * swing_bump(s_fl / 0.75))], -1)
            rel = (1 - leave[:, None]) * relative(t_off, center, z_off) + leave[:, None] * tucked
            rel = (1 - arrive[:, None]) * rel + arrive[:, None] * relative(t_land, land_center, z_land)
            hip = np.concatenate([root_xy[seg], height[seg, None]], -1) + W @ skel.hip_offsets()[side]
            in_air = hip + np.concatenate([yaw_rotate(rel[:, :2], yaw[seg]), rel[:, 2:]], -1)
            ankle[seg, side] = np.where(flying[:, None], in_air, on_floor)
            fyaw[seg, side], fpitch[seg, side] = fy, fp
            free[seg, side] = np.where(flying, leave * (1 - arrive), 0.0)
            flex[seg, side] = 30 * _DEG
        # Arms swing back in the crouch, up through the take-off, forward on landing.
        key_t = [t0, t_low, t_off, t_off + 0.5 * flight, t_land, t_absorb, t_stand]
        up = 60 + rng.uniform(40, 100) * min(1.0, flight / 0.5)  # short hops swing the arms less
        arm_keys = np.array([5, -rng.uniform(30, 55), 60, up, rng.uniform(40, 60), rng.uniform(30, 50), 5])
        arm_flex[seg] = keyframes(ts, key_t, arm_keys * _DEG)
        bend_keys = np.array([0.0, rng.uniform(20, 35), 0.0, 0.0, 0.0, rng.uniform(15, 30), 0.0])
        bend[seg] = keyframes(ts, key_t, bend_keys * _DEG)
        center, heading = land_center, heading + turn
        cursor = end
    pitch = 0.7 * bend
    for side in (0, 1):
        # Raised arms open sideways so that they do not cross overhead.
        abduct = 15 * _DEG + 25 * _DEG * np.clip((arm_flex - 90 * _DEG) / (60 * _DEG), 0.0, 1.0)
        post.arm(side, flex=arm_flex, abduct=abduct, elbow=25 * _DEG + 0.2 * np.abs(arm_flex))
    post.spine(bend=0.5 * bend)
    post.head(nod=-0.6 * bend)
    post.idle(rng, t, 0.5)
    root = np.concatenate([root_xy, height[:, None]], -1)
    return Performance(root, yaw, pitch, np.zeros(T), ankle, fyaw, fpitch, free, flex, post.params)
