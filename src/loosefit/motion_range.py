"""The range of root motion a run was trained on, and a warning when a motion leaves it.

A garment network sees the root through three features (:mod:`loosefit.models.motion_features`): the
root height, its displacement since the previous frame and its heading change since the previous frame.
Outside the values it was trained on it extrapolates, and a garment then stays on the floor while the
body is lifted by a metre, with nothing said. So :func:`loosefit.training.train_model` records in the
run's ``model.json`` the range of the training motions (:class:`MotionRange`, key ``"motion_range"``),
and ``loosefit animate``, ``view RUN:MOTION`` and ``report`` compare each motion with it and print one
warning line per quantity that leaves it (:func:`range_warnings`). Runs trained before the range was
recorded, and methods without training (the body-LBS baseline follows any motion), are not checked.

The quantities, per motion of ``T`` frames at ``fps`` (Z up):

- root height ``z_t`` (metres): its minimum and maximum;
- root horizontal speed ``fps * ||(x, y)_{t+1} - (x, y)_t||`` (m/s): its maximum;
- root turn rate ``fps * |wrap(psi_{t+1} - psi_t)|`` (rad/s) about the up axis, ``psi`` the root's heading
  as the networks see it (:func:`~loosefit.motion.heading.heading_angles`): its maximum.

Tolerances (:data:`HEIGHT_TOLERANCE_M`, :data:`SPEED_TOLERANCE`, :data:`TURN_TOLERANCE`): a motion is
out of range when a value passes the training range by more than the tolerance, so that another take of a
trained kind of motion passes: three seeds of the procedural 3 s walk differ by up to 2.2 cm in their lowest
root height (0.744-0.780 m) and reach 1.08-1.26 m/s and 0.62-0.91 rad/s.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from loosefit.motion.motion import Motion

#: The key of the range in a run's ``model.json``.
META_KEY = "motion_range"
#: Metres the root may go below the lowest or above the highest training root height.
HEIGHT_TOLERANCE_M = 0.05
#: ``(fraction, absolute)``: the speed may exceed the training maximum by ``fraction`` of it plus
#: ``absolute`` m/s (the absolute part covers runs trained on near-still motions).
SPEED_TOLERANCE = (0.25, 0.10)
#: ``(fraction, absolute)``: the same for the turn rate, absolute part in rad/s.
TURN_TOLERANCE = (0.25, 0.25)


def root_heights(motion: Motion) -> np.ndarray:
    """Root height ``(T,)`` float64 metres."""
    return motion.translation[:, 2].astype(np.float64)


def root_speeds(motion: Motion) -> np.ndarray:
    """Root horizontal speed ``(T - 1,)`` float64 m/s between consecutive frames."""
    xy = motion.translation[:, :2].astype(np.float64)
    return np.linalg.norm(np.diff(xy, axis=0), axis=1) * motion.fps


def root_turn_rates(motion: Motion) -> np.ndarray:
    """Root turn rate about the up axis ``(T - 1,)`` float64 rad/s (absolute) between consecutive frames."""
    import torch

    from loosefit.geometry.rotations import axis_angle_to_matrix
    from loosefit.motion.heading import heading_angles

    root = axis_angle_to_matrix(torch.from_numpy(motion.rotations[:, 0]).double()).numpy()
    dpsi = np.diff(heading_angles(root))
    return np.abs((dpsi + np.pi) % (2 * np.pi) - np.pi) * motion.fps


@dataclass(frozen=True)
class MotionRange:
    """The root motion of some motions: height ``height_min``/``height_max`` (m), the largest horizontal
    speed ``speed_max`` (m/s) and turn rate ``turn_rate_max`` (rad/s) about the up axis."""

    height_min: float
    height_max: float
    speed_max: float
    turn_rate_max: float

    @classmethod
    def of(cls, motions: list[Motion]) -> "MotionRange":
        """The range over every frame of ``motions`` (at least one; one-frame motions add no speed or turn)."""
        if not motions:
            raise ValueError("the range of no motions is undefined")
        heights = np.concatenate([root_heights(m) for m in motions])
        speeds = np.concatenate([[0.0]] + [root_speeds(m) for m in motions])
        turns = np.concatenate([[0.0]] + [root_turn_rates(m) for m in motions])
        return cls(float(heights.min()), float(heights.max()), float(speeds.max()), float(turns.max()))

    def to_json(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_meta(cls, meta: dict) -> "MotionRange | None":
        """The range recorded in a run's ``model.json`` content; None when the run has none (trained before
        ranges were recorded, or a method without training) or the record is not a range."""
        record = meta.get(META_KEY)
        if not isinstance(record, dict):
            return None
        try:
            return cls(**{k: float(record[k]) for k in ("height_min", "height_max", "speed_max", "turn_rate_max")})
        except (KeyError, TypeError, ValueError):
            return None

    def problems(self, motion: Motion) -> list[str]:
        """What of ``motion`` leaves this range by more than the tolerances: one text per quantity (root
        height, root horizontal speed, root turn rate), giving the motion's value and the training range."""
        out = []
        heights = root_heights(motion)
        low, high = float(heights.min()), float(heights.max())
        if low < self.height_min - HEIGHT_TOLERANCE_M or high > self.height_max + HEIGHT_TOLERANCE_M:
            out.append(f"root height {low:.3f} to {high:.3f} m, outside the training range {self.height_min:.3f} "
                       f"to {self.height_max:.3f} m (tolerance {HEIGHT_TOLERANCE_M:g} m)")
        speed = float(root_speeds(motion).max(initial=0.0))
        if speed > self.speed_max * (1 + SPEED_TOLERANCE[0]) + SPEED_TOLERANCE[1]:
            out.append(f"root horizontal speed up to {speed:.2f} m/s, above the training maximum "
                       f"{self.speed_max:.2f} m/s (tolerance {SPEED_TOLERANCE[0]:.0%} + {SPEED_TOLERANCE[1]:g} m/s)")
        turn = float(root_turn_rates(motion).max(initial=0.0))
        if turn > self.turn_rate_max * (1 + TURN_TOLERANCE[0]) + TURN_TOLERANCE[1]:
            out.append(f"root turn rate up to {turn:.2f} rad/s, above the training maximum "
                       f"{self.turn_rate_max:.2f} rad/s (tolerance {TURN_TOLERANCE[0]:.0%} + {TURN_TOLERANCE[1]:g} rad/s)")
        return out


def store_motion_range(data: str | Path, sequences: list[str]) -> MotionRange | None:
    """The range of the motions of the store's ``sequences`` over the frames each was simulated for (None
    when there are none)."""
    from loosefit.data.store import DatasetStore

    store = DatasetStore.open(data, mode="r")
    parts: dict[tuple[str, int], Motion] = {}  # sequences of other garments and bodies share motions
    for name in sequences:
        seq = store.sequence(name)
        key = (seq.motion, seq.num_frames)
        if key not in parts:
            parts[key] = store.motion(seq.motion).slice(0, seq.num_frames)
    return MotionRange.of(list(parts.values())) if parts else None


def range_warnings(meta: dict, motion: Motion, label: str | Path | None = None) -> list[str]:
    """One line per quantity of ``motion`` that leaves the training range recorded in the run record
    ``meta`` (``model.json``'s content), naming the motion (``label``, e.g. its file; default: its name),
    the quantity, its value and the range. Empty for a motion in range and for a run without a range."""
    training = MotionRange.from_meta(meta)
    if training is None:
        return []
    name = str(label) if label is not None else (repr(motion.name) if motion.name else "(unnamed)")
    return [f"motion {name}: {p}: the garment may not follow the body" for p in training.problems(motion)]


# --- Coverage: does the training data hold motions like a held-out one? ---------------------------------------
#: rad/s above which the root counts as turning (a walk's heading wobble stays below it; spins reach 6-13 rad/s).
BOUT_RATE = 1.5
#: radians a turn must add up to before it counts as a bout (filters a quick glance).
BOUT_MIN_TURN = 0.5


@dataclass(frozen=True)
class TurnBout:
    """One stretch of turning in one direction: signed total ``turn`` (rad, + counter-clockwise seen from above),
    its largest rate ``peak_rate`` (rad/s, absolute) and its first and last frame (``start``, ``stop`` exclusive)."""

    turn: float
    peak_rate: float
    start: int
    stop: int


def turn_bouts(motion: Motion) -> list[TurnBout]:
    """The root's turn bouts: maximal runs of frames that turn faster than :data:`BOUT_RATE` in one direction and add
    up to at least :data:`BOUT_MIN_TURN`, in order. A spin's bouts give its directions and reversals, a jump's the
    turn it makes in flight."""
    import torch

    from loosefit.geometry.rotations import axis_angle_to_matrix
    from loosefit.motion.heading import heading_angles

    root = axis_angle_to_matrix(torch.from_numpy(motion.rotations[:, 0]).double()).numpy()
    dpsi = np.diff(heading_angles(root))
    rate = ((dpsi + np.pi) % (2 * np.pi) - np.pi) * motion.fps  # (T - 1,) signed, between frames t and t + 1
    sign = np.where(np.abs(rate) > BOUT_RATE, np.sign(rate), 0.0)
    bouts, t = [], 0
    while t < len(rate):
        if sign[t] == 0:
            t += 1
            continue
        stop = t
        while stop < len(rate) and sign[stop] == sign[t]:
            stop += 1
        turn = float(rate[t:stop].sum() / motion.fps)
        if abs(turn) >= BOUT_MIN_TURN:
            bouts.append(TurnBout(turn, float(np.abs(rate[t:stop]).max()), t, stop + 1))
        t = stop
    return bouts


@dataclass(frozen=True)
class MotionExtent:
    """What a motion asks of a garment model beyond the root range: its largest single turn ``max_turn`` (rad) and
    turn rate ``max_rate`` (rad/s) per direction (``ccw``/``cw``), its direction reversals between consecutive
    bouts, and the root's rise above its lowest height ``rise`` (m: jumps)."""

    max_turn_ccw: float
    max_turn_cw: float
    max_rate: float
    reversals: int
    rise: float

    @classmethod
    def of(cls, motion: Motion) -> "MotionExtent":
        bouts = turn_bouts(motion)
        ccw = [b.turn for b in bouts if b.turn > 0]
        cw = [-b.turn for b in bouts if b.turn < 0]
        reversals = sum(1 for a, b in zip(bouts, bouts[1:]) if a.turn * b.turn < 0)
        heights = root_heights(motion)
        return cls(max(ccw, default=0.0), max(cw, default=0.0), max((b.peak_rate for b in bouts), default=0.0),
                   reversals, float(heights.max() - heights.min()))

    def covers(self, other: "MotionExtent", slack: float = 0.85) -> bool:
        """Whether a motion of this extent reaches ``other``'s: its largest turn in each direction, its turn rate
        and its rise each at least ``slack`` of ``other``'s less a small absolute part (:data:`BOUT_MIN_TURN`,
        :data:`BOUT_RATE`, :data:`HEIGHT_TOLERANCE_M`: a walk's 1 cm of bob is no range to cover), and a
        reversal where ``other`` has one."""
        return (self.max_turn_ccw >= slack * other.max_turn_ccw - BOUT_MIN_TURN
                and self.max_turn_cw >= slack * other.max_turn_cw - BOUT_MIN_TURN
                and self.max_rate >= slack * other.max_rate - BOUT_RATE
                and self.rise >= slack * other.rise - HEIGHT_TOLERANCE_M
                and (self.reversals > 0 or other.reversals == 0))

    def to_json(self) -> dict[str, float]:
        return {k: round(v, 4) if isinstance(v, float) else v for k, v in asdict(self).items()}
