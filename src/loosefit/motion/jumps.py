"""Root jumps no person makes: a rest pose a converter put before the motion, takes spliced together.

Some converted motion files start with the skeleton's rest pose (a T-pose at the origin) one frame
before the motion, which starts metres away: played as is, the body teleports between frames 0 and 1.
The importers (:func:`~loosefit.motion.bvh.import_bvh`, :func:`~loosefit.motion.amass.import_amass`)
drop such a first frame unless asked to keep it, and :func:`~loosefit.motion.io.load_motion` warns
about any jump left in the motion it returns.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

#: Root speed (metres per second, 3D, between consecutive frames) beyond which a person does not move:
#: the root jumped. The fastest human sprint peaks at 12.4 m/s, over a track longer than any capture
#: volume. Measured on the 49 CMU clips of ``../shared/mocap/cmu-cc`` at 60 fps (root scaled to the Anny
#: body): the fastest frame-to-frame root speed is 3.3 m/s (playground jumps), 6.9 m/s once where the
#: capture stalls for six frames and catches up in one (003_02, frame 11); the prepended T-poses of the
#: eight "Imported" clips are 103-133 m/s away from frame 1. 10 m/s sits between the two, and the cost of
#: a false alarm is small: one dropped first frame, said on stderr, or a warning.
MAX_ROOT_SPEED = 10.0
#: The flag (and library argument) that keeps a far first frame, named in the note that drops one.
KEEP_HINT = "--keep-first-frame (keep_first_frame=True) keeps it"


def root_speeds(root: np.ndarray, fps: float) -> np.ndarray:
    """``(T - 1,)`` float64 root speed between consecutive frames, m/s, from root positions ``(T, 3)``
    in metres at ``fps`` frames per second."""
    root = np.asarray(root, np.float64)
    return np.linalg.norm(np.diff(root, axis=0), axis=-1) * fps


def far_first_frame(root: np.ndarray, fps: float) -> float | None:
    """The root speed (m/s) from frame 0 to frame 1 when it is beyond :data:`MAX_ROOT_SPEED` (a first
    frame far from the motion, such as a prepended rest pose), else ``None``; ``root (T, 3)`` metres."""
    if len(root) < 2:
        return None
    speed = float(root_speeds(root[:2], fps)[0])
    return speed if speed > MAX_ROOT_SPEED else None


def first_frame_note(path: str | Path | None, root: np.ndarray, fps: float, speed: float) -> str:
    """The one line that says a far first frame was dropped: the file, the frame, how far and the flag
    that keeps it (``root (T, 3)`` metres)."""
    distance = float(np.linalg.norm(np.asarray(root[1], np.float64) - root[0]))
    where = f"{path}: " if path is not None else ""
    return (f"{where}frame 0 is {distance:.2f} m from frame 1 ({speed:.0f} m/s at {fps:g} fps, beyond the "
            f"{MAX_ROOT_SPEED:g} m/s a person moves; a rest pose put before the motion?): dropped, {KEEP_HINT}")


def drop_far_first_frame(root: np.ndarray, fps: float, path: str | Path | None, keep: bool) -> bool:
    """Whether to drop frame 0 of a source whose root moves along ``root (T, 3)`` (metres, ``fps``): true
    when it is far from frame 1 (:func:`far_first_frame`) and ``keep`` is false; then the note
    (:func:`first_frame_note`) is logged as a warning (stderr under the CLI)."""
    speed = far_first_frame(root, fps)
    if speed is None or keep:
        return False
    log.warning("%s", first_frame_note(path, root, fps, speed))
    return True


def jump_frames(root: np.ndarray, fps: float) -> np.ndarray:
    """Frames ``t`` (int64, ascending) after which the root moves faster than :data:`MAX_ROOT_SPEED` to
    frame ``t + 1``; ``root (T, 3)`` metres at ``fps``."""
    return np.flatnonzero(root_speeds(root, fps) > MAX_ROOT_SPEED).astype(np.int64)


def jumps_warning(motion, what: str | Path, shown: int = 5) -> str | None:
    """One line naming the frames of ``motion`` (a :class:`~loosefit.motion.motion.Motion`) between which
    its root jumps (:func:`jump_frames`), with times and speeds (the first ``shown`` of them), or ``None``
    when it has no jump. ``what`` names the motion (its file, or a plan's motion)."""
    frames = jump_frames(motion.translation, motion.fps)
    if not len(frames):
        return None
    speeds = root_speeds(motion.translation, motion.fps)
    listed = "; ".join(f"frames {t} and {t + 1} ({t / motion.fps:.2f} s, {speeds[t]:.0f} m/s)" for t in frames[:shown])
    more = f"; and {len(frames) - shown} more" if len(frames) > shown else ""
    return (f"{what}: the root jumps faster than a person moves (> {MAX_ROOT_SPEED:g} m/s) between {listed}{more} "
            f"of the motion at {motion.fps:g} fps: takes spliced together, or a rest pose left in?")


def warn_jumps(motion, what: str | Path) -> None:
    """Log :func:`jumps_warning` as a warning when ``motion`` has jumps."""
    line = jumps_warning(motion, what)
    if line is not None:
        log.warning("%s", line)
