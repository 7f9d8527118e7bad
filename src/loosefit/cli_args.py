"""Argument checks of the command line: argparse ``type=`` functions (a bad value is a usage error, exit 2,
without a traceback), the check that an output can be written before any work starts, and the options and
help texts several verbs share."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from loosefit.paths import check_writable


def int_at_least(least: int, most: int | None = None):
    """An argparse ``type=``: an integer in ``[least, most]``; anything else is a usage error (exit 2)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < least or (most is not None and value > most):
            bounds = f">= {least}" if most is None else f"in {least}..{most}"
            raise argparse.ArgumentTypeError(f"must be an integer {bounds}, got {value}")
        return value

    return parse


def _finite_float(text: str, zero_allowed: bool, rule: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (0 <= value if zero_allowed else 0 < value) or not value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be {rule}, got {text}")
    return value


def finite_float(text: str) -> float:
    """An argparse ``type=``: any finite number (never NaN or infinite)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return value


def positive_float(text: str) -> float:
    """An argparse ``type=``: a finite number > 0 (frame rates, durations, lengths)."""
    return _finite_float(text, False, "a positive number")


def nonnegative_float(text: str) -> float:
    """An argparse ``type=``: a finite number >= 0 (a start time)."""
    return _finite_float(text, True, "a number >= 0")


def piece_choice(text: str):
    """An argparse ``type=``: ``largest`` or a piece number >= 1 (1 is the largest piece)."""
    if text == "largest":
        return text
    return int_at_least(1)(text)


def writable(path, folder: bool | None = None) -> None:
    """Refuse an output that cannot be written before any work starts (``folder``: default, a path
    without a suffix or ending in ``/``)."""
    if folder is None:
        folder = str(path).endswith(("/", "\\")) or Path(path).suffix == ""
    check_writable(path, folder=folder)


JOINT_MAP_FORMAT = """\
A joint map is a YAML file saying which joint of a BVH skeleton drives which joint of the body's rig
(cmu_mb for the Anny body: Hips, LHipJoint, LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase, LowerBack,
Spine, Spine1, Neck, Neck1, Head, LeftShoulder, LeftArm, LeftForeArm, LeftHand, LThumb,
LeftFingerBase, LeftHandFinger1 and their Right* / R* twins). Built-in maps: cmu, mixamo, cc
(Character Creator), chosen automatically when the names fit; pass any other with --joint-map.

  name: my-skeleton            # optional, default: the file name
  target_rig: cmu_mb           # optional: the rig whose joints are the keys of joints
  joints:                      # required: rig joint: source joint, or a list of alternatives
    Hips: pelvis
    LeftUpLeg: [l_hip, LeftHip]
  ignore: [prop_*, "*_twist"]  # source joints with no rig joint (fnmatch patterns)
  optional: [LeftToeBase]      # rig joints whose source joint may be missing from a file
  calibration: rest            # rest | motion (default: rest when the file's rest pose stands)
  up: y                        # the file's up axis (x, -y, z ...), default: detected
  front: z                     # the file's front axis, default: detected

Source names match with or without a namespace prefix (mixamorig:Hips matches Hips). Every source
joint must be mapped or ignored; the hips, both legs (hip, knee, ankle) and one spine joint must be
mapped. `loosefit motion map FILE.bvh --out MAP.yaml` writes a starting map to check."""


def force_option(sp) -> None:
    """The ``--force`` of every verb whose output could land on a run folder's or a dataset store's own files
    (:func:`loosefit.paths.guard_output` refuses those without it)."""
    sp.add_argument("--force", action="store_true",
                    help="write the output even over a training run folder's own files (its metrics.csv, "
                         "checkpoints/ ...) or inside a dataset store, which is refused otherwise")


def joint_map_option(sp) -> None:
    """The ``--joint-map`` option of every verb that reads a BVH file."""
    sp.add_argument("--joint-map", default=None, metavar="MAP.yaml",
                    help="joint map for a BVH skeleton without a built-in map (cmu, mixamo, cc): a YAML file or a "
                         "built-in name; `loosefit motion map --help` shows the format, `loosefit motion map "
                         "FILE.bvh --out MAP.yaml` writes a starting one")


def keep_first_frame_option(sp) -> None:
    """The ``--keep-first-frame`` option of every verb that imports a BVH or AMASS motion file."""
    sp.add_argument("--keep-first-frame", action="store_true",
                    help="keep a motion file's first frame when the root jumps from it to the next faster than a "
                         "person moves (> 10 m/s: a rest pose a converter put before the motion); by default it is "
                         "dropped, and a line on stderr says so")


def motion_file_options(sp) -> None:
    """The options of every verb that reads motion files: ``--joint-map`` and ``--keep-first-frame``."""
    joint_map_option(sp)
    keep_first_frame_option(sp)


def live_options(sp) -> None:
    """``loosefit view --live RUN [--motion FILE ...]``: the options of the live page (:mod:`loosefit.viz.live`)."""
    sp.add_argument("--live", action="store_true", help="RUN alone: animate the trained garment in the page itself "
                    "(exported once to ONNX, run by onnxruntime-web), switching motions at will")
    sp.add_argument("--motion", action="append", default=[], metavar="FILE", help="with --live: a motion file "
                    "(.bvh / .npz) offered beside the procedural ones (repeat for more)")
