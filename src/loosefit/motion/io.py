"""Load a motion from any supported file onto a body: loosefit ``.npz``, AMASS ``.npz`` or ``.bvh``."""

from __future__ import annotations

from pathlib import Path

from loosefit.errors import InputError
from loosefit.io.npz import npz_names
from loosefit.motion.amass import import_amass
from loosefit.motion.bvh import read_bvh, retarget_bvh
from loosefit.motion.jumps import warn_jumps
from loosefit.motion.motion import DEFAULT_FPS, Motion
from loosefit.motion.joint_map import JointMap


def load_motion(path: str | Path, body, joint_map: JointMap | str | Path | None = None, fps: float = DEFAULT_FPS,
                source_fps: float | None = None, start: float | None = None, seconds: float | None = None,
                keep_first_frame: bool = False) -> Motion:
    """Read a motion file onto ``body``'s rig (:func:`read_motion`) and keep the part from ``start``
    lasting ``seconds`` (:meth:`Motion.cut`; default: all of it; ``start`` counts from the first frame
    kept); errors name the file. A root that still jumps faster than a person moves between two frames
    of the result is warned about, naming the frames (:func:`~loosefit.motion.jumps.jumps_warning`)."""
    motion = read_motion(path, body, joint_map, fps, source_fps, keep_first_frame=keep_first_frame)
    try:
        motion = motion.cut(start, seconds)
    except InputError as e:
        raise InputError(e.problem, Path(path)) from None
    warn_jumps(motion, path)
    return motion


def read_motion(path: str | Path, body, joint_map: JointMap | str | Path | None = None, fps: float = DEFAULT_FPS,
                source_fps: float | None = None, keep_first_frame: bool = False) -> Motion:
    """Read a motion file and return it on ``body``'s rig.

    Dispatch on the content: a ``.bvh`` file is imported with :func:`~loosefit.motion.bvh.import_bvh`
    (``joint_map`` applies); an ``.npz`` with ``rotations`` is a loosefit :class:`Motion` (checked
    against the body's rig, kept at its own frame rate); an ``.npz`` with ``poses`` is AMASS
    (:func:`~loosefit.motion.amass.import_amass`). Imported motions are resampled to ``fps``.

    Args:
        source_fps: the file's frame rate, needed for AMASS files and loosefit motions that store
            none; for files that store one, it must agree with it.
        keep_first_frame: keep the first frame of a BVH or AMASS file even when it is far from the
            next (a rest pose put before the motion), which the import drops by default, saying so
            (:mod:`loosefit.motion.jumps`). A loosefit motion is read as it is either way.

    Raises:
        InputError: naming the file, when it is none of these or is malformed.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("motion file not found", path)
    if path.suffix.lower() == ".bvh":
        bvh = read_bvh(path)
        _check_rate(bvh.fps, source_fps, path)
        return retarget_bvh(bvh, body, joint_map, fps=fps, name=path.stem, keep_first_frame=keep_first_frame)
    if joint_map is not None:
        raise InputError("a joint map applies to BVH files only", path)
    # Damage of any kind (truncated, a flipped byte, pickles) is an InputError naming the file.
    try:
        keys = set(npz_names(path, ".npz"))
    except InputError as e:
        raise InputError(f"not a .bvh or .npz motion file: {e.problem.removeprefix('cannot read .npz: ')}", path) from None
    if "rotations" in keys:
        motion = Motion.load(path, fps=source_fps)
        _check_rate(motion.fps, source_fps, path)
        try:
            body.check_motion(motion)
        except InputError as e:
            raise InputError(e.problem, path) from None
        return motion
    if "poses" in keys:
        return import_amass(path, body, fps=fps, source_fps=source_fps, keep_first_frame=keep_first_frame)
    raise InputError(f"unknown .npz motion: expected 'rotations' (loosefit) or 'poses' (AMASS), found {sorted(keys)}", path)


def _check_rate(rate: float, source_fps: float | None, path: Path) -> None:
    """A frame rate given for a file that stores its own must agree with it."""
    if source_fps is not None and abs(rate - source_fps) > 1e-3 * rate:
        raise InputError(f"the file's frame rate is {rate:g} fps, --fps says {source_fps:g}", path)
