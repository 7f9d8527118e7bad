"""Locomotion generators: walk, run, turn in place, spin. Each returns a :class:`Performance`.

Gaits follow a path (heading and position integrated from a randomly varying speed and turn
rate); every foot is placed under its hip at mid-stance, so the pelvis travels at the gait's speed
while the planted feet stay put. Walks vault over a straight-ish stance leg (the pelvis dips at
double support), runs bounce on a spring-like stance and fly ballistically between steps.
"""

from __future__ import annotations

import numpy as np

from loosefit.motion.curves import integrate, keyframes, ramp, smooth_noise, smoothstep
from loosefit.motion.footsteps import (
    GROUND_TOLERANCE,
    Stance,
    alternating,
    ankle_from_toe,
    foot_track,
    placement,
    settle_height,
)
from loosefit.motion.kinematics import SIDE_SIGN, Performance, Skeleton, root_height_limit, yaw_rotate
from loosefit.motion.posture import Posture

GRAVITY = 9.81
_DEG = np.pi / 180.0


class _Path:
    """A path sampled on a padded time grid: root position ``(N, 2)`` and heading ``(N,)``, with
    interpolation at arbitrary times."""

    def __init__(self, times: np.ndarray, xy: np.ndarray, heading: np.ndarray):
        self.times, self.xy_grid, self.heading_grid = times, xy, heading

    def xy(self, t) -> np.ndarray:
        return np.stack([np.interp(t, self.times, self.xy_grid[:, k]) for k in (0, 1)], -1)

    def heading(self, t) -> np.ndarray:
        return np.interp(t, self.times, self.heading_grid)


def _padded_times(T: int, fps: float, pad: float) -> np.ndarray:
    n = int(np.ceil(pad * fps))
    return np.arange(-n, T + n) / fps


def _feet(t, skel, path: _Path, intervals, width, toe_out, heel, heel_frac, lift, skew=0.0, pivot=0.0, land=0.0,
          free_swing=0.0):
    """Feet of a stepping gait: ankle targets ``(T, 2, 3)``, then foot yaw, pitch, free weight
    and whether the foot is planted, each ``(T, 2)``."""
    ankle = np.zeros((len(t), 2, 3))
    fyaw, fpitch, free, toe_z = (np.zeros((len(t), 2)) for _ in range(4))
    for side in (0, 1):
        stances = []
        for on, off in intervals[side]:
            ref = 0.5 * (on + off)
            toe, yaw = placement(skel, side, path.xy(ref), float(path.heading(ref)), width, 0.0, toe_out)
            stances.append(Stance(on, off, toe, yaw, ref, pivot, heel, heel_frac * (off - on), land, off - on))
        toe, fyaw[:, side], fpitch[:, side], free[:, side] = foot_track(
            t, stances, skel, side, path.heading, lift, skew, free_swing
        )
        ankle[:, side] = ankle_from_toe(skel, side, toe, fyaw[:, side], fpitch[:, side])
        toe_z[:, side] = toe[:, 2]
    return ankle, fyaw, fpitch, free, toe_z < skel.toe_height + GROUND_TOLERANCE


def _run_bounce(t, intervals, period: float, duty: float) -> np.ndarray:
    """Vertical pelvis offset ``(T,)`` of a run: a half-sine dip over each stance and a ballistic
    arc over each flight, matched in position and velocity (zero at touch-down)."""
    stance, flight = duty * period, (0.5 - duty) * period
    dip = GRAVITY * flight * stance / (2 * np.pi)
    v0 = GRAVITY * flight / 2
    z = np.zeros(len(t))
    for on, off in sorted(intervals[0] + intervals[1]):
        m = (t >= on) & (t < off)
        z[m] = -dip * np.sin(np.pi * (t[m] - on) / stance)
        m = (t >= off) & (t < off + flight)
        tau = t[m] - off
        z[m] = v0 * tau - 0.5 * GRAVITY * tau * tau
    return z


def _gait(rng: np.random.Generator, skel: Skeleton, T: int, fps: float, running: bool) -> Performance:
    t = np.arange(T) / fps
    leg = skel.leg_length
    if running:
        cadence, duty = rng.uniform(2.8, 3.3), rng.uniform(0.28, 0.34)
        speed = rng.uniform(1.9, 2.7) * leg / 0.79  # scaled to the body's legs (Anny's average adult: 0.79 m)
    else:
        cadence, duty = rng.uniform(1.6, 2.1), rng.uniform(0.58, 0.64)
        speed = cadence * leg * rng.uniform(0.55, 0.85)
    period = 2.0 / cadence
    te = _padded_times(T, fps, 2 * period + 0.5)
    turn_deg = 0.0 if rng.random() < 0.35 else rng.uniform(10.0, 25.0 if running else 40.0)
    heading = integrate(te, smooth_noise(rng, te, 2.5, turn_deg * _DEG))
    speed_t = speed * (1.0 + smooth_noise(rng, te, 2.0, 0.08))
    path = _Path(te, integrate(te, speed_t[:, None] * np.stack([np.sin(heading), -np.cos(heading)], -1)), heading)

    phase = rng.uniform(0.0, period)
    intervals = alternating(te[0], te[-1], period, duty, phase)
    if running:
        feet = _feet(t, skel, path, intervals, rng.uniform(-0.05, -0.01), rng.uniform(0, 8) * _DEG,
                     rng.uniform(25, 40) * _DEG, 0.5, rng.uniform(0.15, 0.3), skew=1.5, land=rng.uniform(10, 20) * _DEG,
                     free_swing=1.0)
    else:
        feet = _feet(t, skel, path, intervals, rng.uniform(-0.01, 0.03), rng.uniform(2, 10) * _DEG,
                     rng.uniform(20, 32) * _DEG, rng.uniform(0.3, 0.4), rng.uniform(0.04, 0.07))
    ankle, fyaw, fpitch, free, planted = feet
    flex = np.full((T, 2), rng.uniform(5, 20) * _DEG if running else rng.uniform(-10, 0) * _DEG)

    phi = 2 * np.pi * (t - phase) / period  # 0 at left touch-down
    mid = np.pi * duty  # left mid-stance
    heading_t = path.heading(t)
    lateral = (0.008 if running else rng.uniform(0.015, 0.035)) * np.cos(phi - mid)
    root_xy = path.xy(t) + yaw_rotate(np.stack([lateral, np.zeros(T)], -1), heading_t)
    pelvis_turn = rng.uniform(6, 12) * _DEG if running else rng.uniform(3, 8) * _DEG
    yaw = heading_t - pelvis_turn * np.cos(phi)
    roll = -rng.uniform(2, 5) * _DEG * np.cos(phi - mid)
    lean = rng.uniform(3, 8) * _DEG if running else rng.uniform(0, 4) * _DEG
    pitch = lean + 1.0 * _DEG * np.cos(2 * phi)

    if running:
        bounce = _run_bounce(t, intervals, period, duty)
        limit = root_height_limit(skel, root_xy, yaw, pitch, roll, ankle)
        base = np.where(planted, limit - bounce[:, None], np.inf).min()
        base = min(base, skel.root[2]) - 0.005
        height = base + bounce
    else:
        nominal = np.full(T, skel.root[2] - rng.uniform(0.0, 0.03))
        height = settle_height(skel, fps, root_xy, yaw, pitch, roll, ankle, planted, nominal)
    root = np.concatenate([root_xy, height[:, None]], -1)

    post = Posture(skel, T)
    chest_turn = pelvis_turn * rng.uniform(0.3, 0.7)
    post.spine(bend=rng.uniform(4, 10) * _DEG if running else rng.uniform(0, 4) * _DEG,
               side=-roll, twist=(pelvis_turn + chest_turn) * np.cos(phi))
    post.head(nod=-lean * 0.5 + 2 * _DEG * np.cos(2 * phi), turn=-chest_turn * np.cos(phi))
    swing_amp = rng.uniform(30, 45) * _DEG if running else (rng.uniform(8, 16) + 10 * speed) * _DEG
    flex0 = rng.uniform(5, 15) * _DEG if running else rng.uniform(-5, 5) * _DEG
    abduct = rng.uniform(14, 24) * _DEG if running else rng.uniform(10, 16) * _DEG
    elbow0 = rng.uniform(75, 100) * _DEG if running else rng.uniform(15, 30) * _DEG
    lag = rng.uniform(0.0, 0.3)
    for side in (0, 1):
        swing = SIDE_SIGN[side] * -swing_amp * np.cos(phi - lag)  # left arm back at left touch-down
        post.arm(side, flex=flex0 + swing, abduct=abduct, elbow=elbow0 + 0.4 * swing, twist=-5 * _DEG)
    post.idle(rng, t, 0.5)
    return Performance(root, yaw, pitch, roll, ankle, fyaw, fpitch, free, flex, post.params)


def walk(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Walking along a gently curving path: 0.7-1.4 m/s, alternating steps, arms swinging against the legs."""
    return _gait(rng, skel, T, fps, running=False)


def run(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Running at 1.9-2.7 m/s (for 0.79 m legs) with a flight phase between steps, elbows bent, leaning forward."""
    return _gait(rng, skel, T, fps, running=True)


def turn(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Turning on the spot with small steps, 40-200 deg/s, changing direction now and then; the
    planted feet partly pivot with the body."""
    t = np.arange(T) / fps
    cadence, duty = rng.uniform(1.8, 2.6), rng.uniform(0.6, 0.68)
    period = 2.0 / cadence
    te = _padded_times(T, fps, 2 * period + 0.5)
    keys = np.arange(te[0], te[-1] + 2.5, rng.uniform(1.0, 2.5))
    direction = rng.choice([-1.0, 1.0])
    rates = []
    for _ in keys:
        if rng.random() < 0.25:
            direction = -direction
        rates.append(direction * rng.uniform(40, 200) * _DEG)
    rate = keyframes(te, keys, np.array(rates))
    heading = integrate(te, rate)
    drift = np.stack([smooth_noise(rng, te, 3.0, 0.04), smooth_noise(rng, te, 3.0, 0.04)], -1)
    path = _Path(te, drift, heading)

    phase = rng.uniform(0.0, period)
    intervals = alternating(te[0], te[-1], period, duty, phase)
    ankle, fyaw, fpitch, free, planted = _feet(
        t, skel, path, intervals, rng.uniform(0.0, 0.06), rng.uniform(0, 12) * _DEG, rng.uniform(8, 18) * _DEG, 0.3,
        rng.uniform(0.03, 0.06), pivot=rng.uniform(0.4, 0.7),
    )
    phi = 2 * np.pi * (t - phase) / period
    heading_t = path.heading(t)
    lateral = rng.uniform(0.01, 0.025) * np.cos(phi - np.pi * duty)
    root_xy = path.xy(t) + yaw_rotate(np.stack([lateral, np.zeros(T)], -1), heading_t)
    yaw, pitch = heading_t, np.full(T, rng.uniform(0, 4) * _DEG)
    roll = -rng.uniform(1, 3) * _DEG * np.cos(phi - np.pi * duty)
    nominal = np.full(T, skel.root[2] - rng.uniform(0.0, 0.02))
    height = settle_height(skel, fps, root_xy, yaw, pitch, roll, ankle, planted, nominal)

    post = Posture(skel, T)
    lead = np.interp(t + 0.2, te, rate)  # the chest and head anticipate the turn
    post.spine(bend=rng.uniform(0, 5) * _DEG, side=-roll, twist=np.clip(0.12 * lead, -0.35, 0.35))
    post.head(turn=np.clip(0.2 * lead, -0.6, 0.6))
    abduct = rng.uniform(12, 30) * _DEG
    elbow = rng.uniform(20, 60) * _DEG
    for side in (0, 1):
        post.arm(side, flex=rng.uniform(0, 20) * _DEG, abduct=abduct + 0.05 * np.abs(lead), elbow=elbow)
    post.idle(rng, t, 1.0)
    root = np.concatenate([root_xy, height[:, None]], -1)
    return Performance(root, yaw, pitch, roll, ankle, fyaw, fpitch, free, np.zeros((T, 2)), post.params)


_SPIN_ARMS = {  # arm poses while spinning: (flex, abduct, elbow) ranges in degrees
    "open": ((0, 25), (70, 100), (10, 40)),
    "high": ((0, 20), (130, 165), (20, 50)),
    "round": ((55, 80), (35, 55), (60, 90)),
}
_SPIN_ARMS_ODDS = (0.6, 0.25, 0.15)
_FREE_LEG = {  # where the lifted foot's ankle goes: offsets from the pelvis (outward, backward, down), metres
    "passe": ((0.06, 0.1), (-0.14, -0.06), (0.42, 0.52)),
    "attitude": ((0.08, 0.14), (0.2, 0.32), (0.5, 0.6)),
    "low": ((0.1, 0.16), (-0.1, 0.05), (0.6, 0.68)),
}


def spin(rng: np.random.Generator, skel: Skeleton, T: int, fps: float) -> Performance:
    """Fast spins on one foot (1-2 turns per second, arms out; a dancer's pirouette turns about twice a
    second, and faster spins fling a skirt straight out): each bout shifts the weight onto
    one foot, rises onto its ball, pivots several turns with the other leg lifted, lands that foot
    and settles; bouts alternate feet and pick their own direction, speed and arm style."""
    t = np.arange(T) / fps
    cursor = -rng.uniform(0.0, 1.5)
    stance = int(rng.integers(2))
    height_z = skel.root[2] - rng.uniform(0.0, 0.03)
    bouts = []
    while cursor < T / fps:
        b = dict(start=cursor, stance=stance, prep=rng.uniform(0.35, 0.6), up=rng.uniform(0.3, 0.5),
                 hold=rng.uniform(0.6, 2.5), down=rng.uniform(0.35, 0.55), settle=rng.uniform(0.3, 0.6),
                 rate=rng.choice([-1.0, 1.0]) * rng.uniform(1.0, 2.0) * 2 * np.pi,
                 releve=rng.uniform(15, 28) * _DEG, turnout=rng.uniform(15, 40) * _DEG)
        b["spin_on"] = cursor + b["prep"]
        b["spin_off"] = b["spin_on"] + b["up"] + b["hold"] + b["down"]
        b["end"] = b["spin_off"] + b["settle"]
        arms = _SPIN_ARMS[rng.choice(list(_SPIN_ARMS), p=_SPIN_ARMS_ODDS)]
        b["arm_at"] = np.array([rng.uniform(*r) for r in arms]) * _DEG
        b["free_at"] = np.array([rng.uniform(*r) for r in _FREE_LEG[rng.choice(list(_FREE_LEG))]])
        bouts.append(b)
        cursor = b["end"]
        stance = 1 - stance if rng.random() < 0.7 else stance
    te = np.arange(bouts[0]["start"] - 0.1, cursor + 0.1 + 1 / fps, 1 / fps)
    rate = sum(b["rate"] * _spin_envelope(te, b) for b in bouts)
    heading_grid = integrate(te, rate, at=te[0])
    heading = lambda x: np.interp(x, te, heading_grid)  # noqa: E731
    psi = heading(t)

    toe_out = rng.uniform(0, 10) * _DEG
    toes = [placement(skel, side, np.zeros(2), 0.0, 0.0, 0.0, toe_out) for side in (0, 1)]
    rest_center = 0.5 * (skel.toe[0, 1] + skel.toe[1, 1]) - skel.root[1]

    ankle = np.zeros((T, 2, 3))
    fyaw, fpitch, free_w, flex = np.zeros((T, 2)), np.zeros((T, 2)), np.zeros((T, 2)), np.zeros((T, 2))
    root_xy = np.zeros((T, 2))
    post = Posture(skel, T)
    arms, windup = np.zeros((T, 3)), np.zeros(T)
    relaxed = np.array([0.0, 12 * _DEG, 20 * _DEG])
    for k, b in enumerate(bouts):
        last = k == len(bouts) - 1
        inside = (t >= b["start"]) & ((t < b["end"]) | last)
        if k == 0:
            inside |= t < b["start"]
        s, f = b["stance"], 1 - b["stance"]
        p_s, y_s = toes[s]
        p_f, y_f = toes[f]
        psi_end = float(heading(b["spin_off"]))
        land_toe = p_s + yaw_rotate(skel.toe[f, :2] - skel.toe[s, :2], psi_end)
        land_yaw = psi_end + SIDE_SIGN[f] * toe_out
        tb = t[inside]
        n = inside.sum()
        u = ramp(tb, b["start"], b["prep"]) * (1 - ramp(tb, b["spin_off"], b["settle"]))  # weight on the stance foot
        # Stance foot: pivots with the body on its ball.
        rise = ramp(tb, b["spin_on"] - 0.2, b["up"]) * (1 - ramp(tb, b["spin_off"] - 0.1, b["settle"]))
        pitch_s = b["releve"] * rise
        yaw_s = y_s + (psi[inside] - heading(b["start"]))
        toe_s = np.concatenate([np.broadcast_to(p_s, (n, 2)), np.full((n, 1), skel.toe_height)], -1)
        ankle[inside, s] = ankle_from_toe(skel, s, toe_s, yaw_s, pitch_s)
        fyaw[inside, s], fpitch[inside, s] = yaw_s, pitch_s
        # Root: from between the feet over to the ball of the stance foot.
        center = np.array([SIDE_SIGN[s] * 0.015, -0.02])
        over = p_s - yaw_rotate(np.broadcast_to(center, (n, 2)), psi[inside])
        landed = tb >= b["spin_off"]
        mid_toes = np.where(landed[:, None], 0.5 * (p_s + land_toe), 0.5 * (p_s + p_f))
        between = mid_toes - yaw_rotate(np.stack([np.zeros(n), np.full(n, rest_center)], -1), psi[inside])
        root_xy[inside] = (1 - u[:, None]) * between + u[:, None] * over
        # Free foot: heel up, into the air beside the stance leg, back down beside it.
        lift_on, land_on = b["spin_on"] + 0.05, b["spin_off"] - 0.35
        up = ramp(tb, lift_on, 0.3) * (1 - ramp(tb, land_on, 0.3))
        heel_f = 25 * _DEG * ramp(tb, lift_on - 0.2, 0.2) * (1 - ramp(tb, land_on + 0.2, 0.15))
        moved = tb >= 0.5 * (lift_on + 0.3 + land_on)  # switch spots while the foot is fully up
        yaw_ground = np.where(moved, land_yaw, y_f)
        toe_ground = np.where(moved[:, None], land_toe, p_f)
        toe_ground = np.concatenate([toe_ground, np.full((n, 1), skel.toe_height)], -1)
        ground = ankle_from_toe(skel, f, toe_ground, yaw_ground, heel_f)
        out, back, down = b["free_at"]
        air_off = np.broadcast_to(np.array([SIDE_SIGN[f] * out, back]), (n, 2))
        air = np.concatenate([over + yaw_rotate(air_off, psi[inside]), np.full((n, 1), height_z - down)], -1)
        ankle[inside, f] = (1 - up[:, None]) * ground + up[:, None] * air
        fyaw[inside, f] = (1 - up) * yaw_ground + up * (psi[inside] + SIDE_SIGN[f] * b["turnout"])
        fpitch[inside, f] = heel_f
        free_w[inside, f] = smoothstep((up - 0.3) / 0.7)
        flex[inside, f] = 30 * _DEG
        # Arms open with the weight shift; the chest winds up against the turn before it.
        arms[inside] = (1 - u[:, None]) * relaxed + u[:, None] * b["arm_at"]
        windup[inside] = -np.sign(b["rate"]) * 12 * _DEG * (
            ramp(tb, b["start"], b["prep"]) - ramp(tb, b["spin_on"], b["up"])
        )
        toes[f] = (land_toe, land_yaw)
        toes[s] = (p_s, y_s + psi_end - float(heading(b["start"])))  # the stance foot pivoted
    post.spine(twist=windup)
    for side in (0, 1):
        post.arm(side, flex=arms[:, 0], abduct=arms[:, 1], elbow=arms[:, 2])
    post.idle(rng, t, 0.5)
    yaw, pitch, roll = psi, np.full(T, rng.uniform(0, 3) * _DEG), np.zeros(T)
    height = settle_height(skel, fps, root_xy, yaw, pitch, roll, ankle, free_w == 0, np.full(T, height_z))
    root = np.concatenate([root_xy, height[:, None]], -1)
    return Performance(root, yaw, pitch, roll, ankle, fyaw, fpitch, free_w, flex, post.params)


def _spin_envelope(t: np.ndarray, bout: dict) -> np.ndarray:
    """``(T,)`` 0 -> 1 -> 0: a spin bout's turn rate ramping up from ``spin_on`` over ``up`` seconds
    and down to zero at ``spin_off`` over ``down`` seconds."""
    return ramp(t, bout["spin_on"], bout["up"]) * (1 - ramp(t, bout["spin_off"] - bout["down"], bout["down"]))
