"""BVH motion files: parser, writer, forward kinematics and import onto a body rig.

A BVH file has a HIERARCHY (a tree of ``ROOT`` / ``JOINT`` / ``End Site`` blocks, each with an
``OFFSET`` from its parent and ``CHANNELS`` naming the per-frame values it reads) and a MOTION
section (``Frames:``, ``Frame Time:`` and one line of channel values per frame). Rotation channels
are Euler angles in degrees, applied as *intrinsic* rotations in the order the channels are listed
(``Zrotation Yrotation Xrotation`` means ``R = Rz @ Ry @ Rx``), in the frame of the joint, which
its parent's rotation carries.

Position channels are the joint's translation from its parent. Files disagree on whether they
replace the ``OFFSET`` (Blender, most exporters: ``"absolute"``) or are added to it (some converters:
``"relative"``); :func:`read_bvh` decides per file from the data (see :func:`_position_mode`).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.rotations import euler_to_matrix, matrix_to_euler
from loosefit.motion.motion import DEFAULT_FPS, Motion
from loosefit.motion.axes import detect_axes
from loosefit.motion.joint_map import JointMap, resolve_joint_map
from loosefit.motion.jumps import drop_far_first_frame
from loosefit.motion.retarget import SourceAnimation, retarget, source_root_path, to_motion
from loosefit.motion.rig import TargetRig
from loosefit.paths import atomic_path

#: Channel names a BVH joint may list.
CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
#: Name given to ``End Site`` blocks: ``"<parent name>/End Site"`` (no real joint contains a ``/``).
END_SITE = "/End Site"


@dataclass
class BvhData:
    """The content of a BVH file.

    Attributes:
        names: ``J`` joint names in file order; an ``End Site`` is named ``"<parent>/End Site"``.
        parents: ``(J,)`` int64 parent index, -1 for the root (the first joint).
        offsets: ``(J, 3)`` float64 offsets from the parent in the parent's frame, file units.
        channels: per joint, the channel names it reads in order (empty for End Sites).
        frames: ``(T, C)`` float64 channel values of every frame, ``C = sum(len(c) for c in channels)``;
            rotations in degrees, positions in file units.
        frame_time: seconds per frame.
        position_mode: ``"absolute"`` (position channels replace OFFSET) or ``"relative"`` (added to it).
        path: the file it was read from, if any (for error messages).
    """

    names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    channels: list[list[str]]
    frames: np.ndarray
    frame_time: float
    position_mode: str = "absolute"
    path: Path | None = field(default=None, compare=False)

    def __post_init__(self):
        self.parents = np.asarray(self.parents, dtype=np.int64)
        self.offsets = np.asarray(self.offsets, dtype=np.float64).reshape(-1, 3)
        self.frames = np.asarray(self.frames, dtype=np.float64).reshape(len(self.frames), -1)
        self.channels = [list(c) for c in self.channels]
        n = len(self.names)
        if not (self.parents.shape == (n,) and self.offsets.shape == (n, 3) and len(self.channels) == n):
            raise InputError(f"BVH skeleton arrays disagree: {n} names, parents {self.parents.shape}, "
                             f"offsets {self.offsets.shape}, {len(self.channels)} channel lists", self.path)
        if n == 0 or self.parents[0] != -1 or (self.parents[1:] >= np.arange(1, n)).any() or (self.parents[1:] < 0).any():
            raise InputError("BVH joint 0 must be the only root and every parent must come before its children", self.path)
        if self.frames.shape[1] != self.num_channels:
            raise InputError(f"BVH frames have {self.frames.shape[1]} values, the hierarchy declares "
                             f"{self.num_channels} channels", self.path)
        if self.position_mode not in ("absolute", "relative"):
            raise InputError(f"BVH position_mode must be 'absolute' or 'relative', got {self.position_mode!r}", self.path)
        if not self.frame_time > 0:
            raise InputError(f"BVH frame time must be positive, got {self.frame_time}", self.path)

    @property
    def num_frames(self) -> int:
        return self.frames.shape[0]

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    @property
    def fps(self) -> float:
        """Frames per second; ``1 / frame_time`` snapped to the nearest integer when within 0.1 %
        (files print ``0.008333`` for 120 fps)."""
        fps = 1.0 / self.frame_time
        return float(round(fps)) if abs(fps - round(fps)) < 1e-3 * fps else fps

    def is_end_site(self) -> np.ndarray:
        """``(J,)`` bool: which entries are End Sites rather than joints."""
        return np.array([n.endswith(END_SITE) for n in self.names])

    def local_transforms(self, frames: slice | np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Per-frame local rotations ``(T, J, 3, 3)`` and translations ``(T, J, 3)`` (file units)."""
        values = self.frames if frames is None else self.frames[frames]
        T, J = values.shape[0], len(self.names)
        rot = np.broadcast_to(np.eye(3), (T, J, 3, 3)).copy()
        trans = np.broadcast_to(self.offsets, (T, J, 3)).copy()
        col = 0
        for j, chans in enumerate(self.channels):
            axes, angles = "", []
            for c in chans:
                axis = "XYZ".index(c[0])
                if c.endswith("position"):
                    base = self.offsets[j, axis] if self.position_mode == "relative" else 0.0
                    trans[:, j, axis] = base + values[:, col]
                else:
                    axes += c[0].lower()
                    angles.append(values[:, col])
                col += 1
            if axes:
                # Axes without a channel rotate by 0: append them so the order is a full permutation.
                rest = [a for a in "xyz" if a not in axes]
                angles += [np.zeros(T)] * len(rest)
                euler = np.radians(np.stack(angles, -1))
                rot[:, j] = euler_to_matrix(torch.from_numpy(euler), axes + "".join(rest)).numpy()
        return rot, trans

    def world(self, frames: slice | np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics: world joint positions ``(T, J, 3)`` (file units and axes) and world
        joint rotations ``(T, J, 3, 3)`` of the chosen frames (all by default)."""
        rot, trans = self.local_transforms(frames)
        return _chain(rot, trans, self.parents)

    def rest_world(self) -> tuple[np.ndarray, np.ndarray]:
        """The skeleton with every channel at zero rotation and the root at its OFFSET:
        positions ``(J, 3)`` and rotations ``(J, 3, 3)`` (identity)."""
        J = len(self.names)
        pos, rot = _chain(np.broadcast_to(np.eye(3), (1, J, 3, 3)), self.offsets[None], self.parents)
        return pos[0], rot[0]

    def select(self, frames: slice | np.ndarray) -> "BvhData":
        """A copy with only the chosen frames."""
        return BvhData(self.names, self.parents, self.offsets, self.channels, self.frames[frames],
                       self.frame_time, self.position_mode, self.path)


def _chain(rot: np.ndarray, trans: np.ndarray, parents: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Accumulate local transforms down the tree (parents come before children in BVH order)."""
    world_R = np.empty_like(rot)
    world_p = np.empty(rot.shape[:2] + (3,))
    for j, p in enumerate(parents):
        if p < 0:
            world_R[:, j] = rot[:, j]
            world_p[:, j] = trans[:, j]
        else:
            world_R[:, j] = world_R[:, p] @ rot[:, j]
            world_p[:, j] = world_p[:, p] + np.einsum("tab,tb->ta", world_R[:, p], trans[:, j])
    return world_p, world_R


# ----------------------------------------------------------------------------------------- import


def import_bvh(
    path: str | Path,
    body,
    joint_map: JointMap | str | Path | None = None,
    *,
    up: str | None = None,
    front: str | None = None,
    fps: float = DEFAULT_FPS,
    keep_first_frame: bool = False,
) -> Motion:
    """Read a BVH file and retarget it onto ``body``'s rig (see :func:`retarget_bvh`; a first frame far
    from the motion is dropped unless ``keep_first_frame``).

    Returns:
        A :class:`Motion` on ``body.rig`` named after the file.
    """
    path = Path(path)
    return retarget_bvh(read_bvh(path), body, joint_map, up=up, front=front, fps=fps, name=path.stem,
                        keep_first_frame=keep_first_frame)


def retarget_bvh(
    bvh: BvhData,
    body,
    joint_map: JointMap | str | Path | None = None,
    *,
    up: str | None = None,
    front: str | None = None,
    fps: float = DEFAULT_FPS,
    name: str = "",
    keep_first_frame: bool = False,
) -> Motion:
    """Retarget BVH content onto ``body``'s rig.

    Args:
        bvh: the parsed file (any skeleton, Y or Z up, any unit, any frame rate).
        body: a :class:`~loosefit.body.BodyModel` (its rig, joint names and rest joints).
        joint_map: a :class:`~loosefit.motion.joint_map.JointMap`, a built-in map name (``"cmu"``,
            ``"mixamo"``, ``"cc"``), a YAML map file, or ``None`` to pick the built-in map that fits.
        up, front: the file's up and front axes (``"y"``, ``"-z"``...); default: the map's, else
            detected (:func:`~loosefit.motion.axes.detect_axes`).
        fps: output frame rate; the motion is resampled (slerp rotations, lerp translation).
        name: the motion's name.
        keep_first_frame: keep frame 0 even when the root jumps from it to frame 1 faster than a person
            moves (:func:`~loosefit.motion.jumps.far_first_frame`: converters put the rest pose there).
            By default such a frame is dropped before anything is computed from the frames (axes,
            calibration, floor), and a warning names the file.
    """
    target = TargetRig.from_body(body)
    resolved = resolve_joint_map(bvh.names, bvh.parents, target, joint_map, bvh.path, skip=bvh.is_end_site())
    positions, rotations = bvh.world()
    rest_pos, rest_rot = bvh.rest_world()
    root = source_root_path(positions[:2], rest_pos, target, resolved, bvh.path)
    if drop_far_first_frame(root, bvh.fps, bvh.path, keep_first_frame):
        positions, rotations = positions[1:], rotations[1:]
    A = detect_axes(positions, resolved, target, up or resolved.joint_map.up, front or resolved.joint_map.front, bvh.path)
    source = SourceAnimation(
        joint_names=bvh.names,
        parents=bvh.parents,
        positions=positions @ A.T,
        rotations=A @ rotations @ A.T,
        fps=bvh.fps,
        rest_positions=rest_pos @ A.T,
        rest_rotations=A @ rest_rot @ A.T,
    )
    local, root = retarget(source, target, resolved, path=bvh.path)
    return to_motion(local, root, bvh.fps, target, name, fps)


# ----------------------------------------------------------------------------------------- reading


#: The most joints (end sites included) a BVH hierarchy may have; mocap skeletons have 20-300.
MAX_BVH_JOINTS = 1024
#: The deepest chain of joints from the root (the root is 1); a mocap hand is about 15 deep.
MAX_BVH_DEPTH = 128


class _Tokens:
    """Whitespace tokens of the HIERARCHY section with their line numbers, for error messages."""

    def __init__(self, lines: list[str], path: Path):
        self.items = [(tok, n + 1) for n, line in enumerate(lines) for tok in line.split()]
        self.pos = 0
        self.path = path
        self.last_line = len(lines)

    def error(self, problem: str, line: int | None = None) -> InputError:
        line = line if line is not None else self.peek_line()
        return InputError(f"line {line}: {problem}", self.path)

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.pos < len(self.items) else None

    def peek_line(self) -> int:
        return self.items[self.pos][1] if self.pos < len(self.items) else self.last_line

    def next(self, what: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            raise self.error(f"unexpected end of file, expected {what}")
        item = self.items[self.pos]
        self.pos += 1
        return item

    def expect(self, word: str) -> None:
        tok, line = self.next(repr(word))
        if tok.upper() != word.upper():
            raise self.error(f"expected {word!r}, got {tok!r}", line)

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        try:
            value = float(tok)
        except ValueError:
            raise self.error(f"expected a number ({what}), got {tok!r}", line) from None
        if not math.isfinite(value):
            raise self.error(f"{what} is not finite: {tok!r}", line)
        return value


def read_bvh(path: str | Path) -> BvhData:
    """Parse a BVH file.

    Any skeleton, any rotation order, any subset of the six channels per joint. Errors
    (:class:`~loosefit.errors.InputError`) name the file and the line.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="strict")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read BVH file: {e}", path) from None
    lines = text.splitlines()
    motion_at = next((n for n, line in enumerate(lines) if line.strip().upper() == "MOTION"), None)
    if motion_at is None:
        raise InputError("no MOTION section: not a BVH file or the file is truncated", path)
    tokens = _Tokens(lines[:motion_at], path)
    tokens.expect("HIERARCHY")
    names, parents, offsets, channels = [], [], [], []
    tok, line = tokens.next("ROOT")
    if tok.upper() != "ROOT":
        raise tokens.error(f"expected 'ROOT', got {tok!r}", line)
    _parse_joint(tokens, -1, names, parents, offsets, channels)
    if tokens.peek() is not None:
        raise tokens.error(f"unexpected {tokens.peek()!r} after the root joint (only one ROOT is supported)")
    frame_time, frames = _parse_motion(lines, motion_at, sum(len(c) for c in channels), path)
    mode = _position_mode(np.array(offsets), channels, frames)
    return BvhData(names, np.array(parents), np.array(offsets), channels, frames, frame_time, mode, path)


def _parse_joint(tokens: _Tokens, parent: int, names, parents, offsets, channels, depth: int = 1) -> None:
    """Parse ``NAME { OFFSET .. CHANNELS .. children }`` after the ROOT/JOINT keyword (``depth``: 1 for the root)."""
    name, line = tokens.next("a joint name")
    if name == "{":
        raise tokens.error("joint without a name", line)
    if depth > MAX_BVH_DEPTH:
        raise tokens.error(f"joint {name!r} is {depth} joints deep in the hierarchy, deeper than loosefit reads "
                           f"({MAX_BVH_DEPTH}: loosefit.motion.bvh.MAX_BVH_DEPTH)", line)
    if len(names) >= MAX_BVH_JOINTS:
        raise tokens.error(f"the hierarchy has more than {MAX_BVH_JOINTS} joints and end sites, more than loosefit "
                           "reads (loosefit.motion.bvh.MAX_BVH_JOINTS)", line)
    if name in names:
        raise tokens.error(f"duplicate joint name {name!r}", line)
    index = len(names)
    names.append(name)
    parents.append(parent)
    tokens.expect("{")
    tokens.expect("OFFSET")
    offsets.append([tokens.number(f"OFFSET of {name}") for _ in range(3)])
    tokens.expect("CHANNELS")
    count_line = tokens.peek_line()
    count = tokens.number(f"channel count of {name}")
    if count != int(count) or not 0 <= count <= 6:
        raise tokens.error(f"joint {name!r}: channel count must be 0..6, got {count:g}", count_line)
    chans = []
    for _ in range(int(count)):
        tok, line = tokens.next(f"a channel name of {name}")
        if tok not in CHANNEL_NAMES:
            raise tokens.error(f"joint {name!r} declares {int(count)} channels but {tok!r} is not a channel "
                               f"name (expected one of {list(CHANNEL_NAMES)})", line)
        if tok in chans:
            raise tokens.error(f"joint {name!r} lists channel {tok!r} twice", line)
        chans.append(tok)
    if tokens.peek() in CHANNEL_NAMES:
        raise tokens.error(f"joint {name!r} declares {int(count)} channels but lists more")
    channels.append(chans)
    while True:
        tok, line = tokens.next(f"JOINT, End Site or '}}' closing {name!r}")
        key = tok.upper()
        if key == "}":
            return
        if key == "JOINT":
            _parse_joint(tokens, index, names, parents, offsets, channels, depth + 1)
        elif key == "END":
            if len(names) >= MAX_BVH_JOINTS:
                raise tokens.error(f"the hierarchy has more than {MAX_BVH_JOINTS} joints and end sites, more than "
                                   "loosefit reads (loosefit.motion.bvh.MAX_BVH_JOINTS)", line)
            tokens.expect("Site")
            tokens.expect("{")
            tokens.expect("OFFSET")
            names.append(name + END_SITE)
            parents.append(index)
            offsets.append([tokens.number(f"End Site OFFSET of {name}") for _ in range(3)])
            channels.append([])
            tokens.expect("}")
        else:
            raise tokens.error(f"expected JOINT, End Site or '}}' in joint {name!r}, got {tok!r}", line)


def _parse_motion(lines: list[str], motion_at: int, num_channels: int, path: Path) -> tuple[float, np.ndarray]:
    """Parse ``Frames:``, ``Frame Time:`` and the frame lines after the MOTION keyword."""
    header = [(n, line.strip()) for n, line in enumerate(lines[motion_at + 1 :], motion_at + 2) if line.strip()]

    def field_value(i: int, label: str) -> tuple[float, int]:
        if i >= len(header):
            raise InputError(f"line {len(lines)}: truncated MOTION section, expected {label!r}", path)
        n, line = header[i]
        if not line.lower().startswith(label.lower()):
            raise InputError(f"line {n}: expected {label!r}, got {line[:40]!r}", path)
        try:
            return float(line[len(label) :]), n
        except ValueError:
            raise InputError(f"line {n}: {label!r} is not followed by a number", path) from None

    num_frames, n = field_value(0, "Frames:")
    if num_frames != int(num_frames) or num_frames < 1:
        raise InputError(f"line {n}: Frames must be a positive integer, got {num_frames:g}", path)
    frame_time, n = field_value(1, "Frame Time:")
    if not frame_time > 0:
        raise InputError(f"line {n}: Frame Time must be positive, got {frame_time:g}", path)
    body = header[2:]
    num_frames = int(num_frames)
    if len(body) < num_frames:
        raise InputError(f"truncated motion: Frames: {num_frames} but only {len(body)} frame lines", path)
    if len(body) > num_frames:
        raise InputError(f"line {body[num_frames][0]}: more frame lines than Frames: {num_frames}", path)
    rows = [line.split() for _, line in body]
    for (n, _), row in zip(body, rows):
        if len(row) != num_channels:
            raise InputError(f"line {n}: frame has {len(row)} values, the hierarchy declares {num_channels} channels", path)
    try:
        frames = np.array(rows, dtype=np.float64).reshape(num_frames, num_channels)
    except ValueError:
        for (n, _), row in zip(body, rows):
            for tok in row:
                try:
                    float(tok)
                except ValueError:
                    raise InputError(f"line {n}: frame value {tok!r} is not a number", path) from None
        raise
    if not np.isfinite(frames).all():
        n = body[int(np.argwhere(~np.isfinite(frames))[0, 0])][0]
        raise InputError(f"line {n}: frame values must be finite", path)
    return frame_time, frames


def _position_mode(offsets: np.ndarray, channels: list[list[str]], frames: np.ndarray) -> str:
    """Whether position channels replace the OFFSET or add to it, decided on the root.

    With ``m`` the mean root position channels and ``o`` the root OFFSET: channels that replace the
    offset hover around it (``m . o ~ |o|^2``), channels added to it hover around zero (``m . o ~ 0``);
    split at half. Travel across the floor is perpendicular to a vertical offset and does not move
    the split. A zero offset makes both readings equal.
    """
    pos = [i for i, c in enumerate(channels[0]) if c.endswith("position")]
    offset = offsets[0]
    if not pos or float(offset @ offset) == 0.0:
        return "absolute"
    mean = np.zeros(3)
    for i in pos:
        mean["XYZ".index(channels[0][i][0])] = frames[:, i].mean()
    return "absolute" if mean @ offset > 0.5 * (offset @ offset) else "relative"


# ----------------------------------------------------------------------------------------- writing


def write_bvh(path: str | Path, bvh: BvhData, precision: int = 6) -> None:
    """Write ``bvh`` as a BVH file, atomically. Position channels are written as they are stored
    (``bvh.position_mode`` says how a reader should take them; :func:`read_bvh` decides from the data)."""
    out = io.StringIO()
    out.write("HIERARCHY\n")
    children = _children(bvh.parents)
    order = _depth_first(children)
    # Frame values follow the order joints appear in the file: depth first.
    starts = np.cumsum([0] + [len(c) for c in bvh.channels])
    columns = np.concatenate([np.arange(starts[j], starts[j + 1]) for j in order]).astype(np.int64)

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        off = " ".join(f"{v:.{precision}f}" for v in bvh.offsets[j])
        if bvh.names[j].endswith(END_SITE):
            out.write(f"{pad}End Site\n{pad}{{\n{pad}  OFFSET {off}\n{pad}}}\n")
            return
        out.write(f"{pad}{'ROOT' if bvh.parents[j] < 0 else 'JOINT'} {bvh.names[j]}\n{pad}{{\n")
        out.write(f"{pad}  OFFSET {off}\n")
        out.write(f"{pad}  CHANNELS {len(bvh.channels[j])}{''.join(' ' + c for c in bvh.channels[j])}\n")
        for c in children[j]:
            emit(c, depth + 1)
        out.write(f"{pad}}}\n")

    emit(0, 0)
    out.write(f"MOTION\nFrames: {bvh.num_frames}\nFrame Time: {bvh.frame_time:.{max(precision, 8)}f}\n")
    np.savetxt(out, bvh.frames[:, columns], fmt=f"%.{precision}f", delimiter=" ")
    with atomic_path(path) as tmp:
        tmp.write_text(out.getvalue(), encoding="utf-8")


def skeleton_to_bvh(
    names: list[str],
    parents: np.ndarray,
    rest_joints: np.ndarray,
    local_rotations: np.ndarray,
    root_positions: np.ndarray,
    fps: float,
    order: str = "ZYX",
    up: str = "z",
    scale: float = 1.0,
) -> BvhData:
    """A BVH of a skeleton in loosefit's rig convention (world-aligned joint frames at rest).

    Args:
        names: ``J`` joint names (parents before children).
        parents: ``(J,)`` parent indices, -1 for the root (joint 0).
        rest_joints: ``(J, 3)`` rest joint positions, metres, Z up.
        local_rotations: ``(T, J, 3, 3)`` local rotations in world-aligned axes (``W_j = W_parent @ R_j``).
        root_positions: ``(T, 3)`` world positions of the root joint, metres, Z up.
        fps: frame rate.
        order: rotation channel order, a permutation of ``"XYZ"`` (intrinsic, as BVH reads it).
        up: ``"z"`` to keep Z up, ``"y"`` to write Y up (Z up -> Y up, -Y front -> +Z front).
        scale: file units per metre (100 for centimetres).

    Returns:
        BvhData with a 6-channel root, 3-channel joints and an End Site under every leaf.
    """
    parents = np.asarray(parents)
    if parents[0] != -1 or any(p >= j for j, p in enumerate(parents) if j > 0):
        raise InputError("skeleton_to_bvh needs joint 0 as root and parents before children")
    order = order.upper()
    if sorted(order) != ["X", "Y", "Z"]:
        raise InputError(f"BVH rotation order must be a permutation of XYZ, got {order!r}")
    if up not in ("y", "z"):
        raise InputError(f"BVH up axis must be 'y' or 'z', got {up!r}")
    A = np.eye(3) if up == "z" else np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    rest = np.asarray(rest_joints, np.float64) @ A.T * scale
    local = A @ np.asarray(local_rotations, np.float64) @ A.T
    euler = np.degrees(matrix_to_euler(torch.from_numpy(local), order.lower()).numpy())  # (T, J, 3)
    root = np.asarray(root_positions, np.float64) @ A.T * scale
    J = len(names)
    is_leaf = np.ones(J, bool)
    is_leaf[parents[parents >= 0]] = False
    leaves = np.flatnonzero(is_leaf)
    offsets = [rest[0]] + [rest[j] - rest[parents[j]] for j in range(1, J)]
    # A short End Site along +up under every leaf: BVH viewers need one to draw the leaf bone.
    offsets += [A @ np.array([0.0, 0.0, 0.05]) * scale] * len(leaves)
    rotation_channels = [f"{a}rotation" for a in order]
    channels = [[f"{a}position" for a in "XYZ"] + rotation_channels] + [rotation_channels] * (J - 1)
    return BvhData(
        names=list(names) + [names[j] + END_SITE for j in leaves],
        parents=np.concatenate([parents, leaves]),
        offsets=np.array(offsets),
        channels=channels + [[]] * len(leaves),
        frames=np.concatenate([root, euler.reshape(len(root), -1)], 1),
        frame_time=1.0 / fps,
    )


def _children(parents: np.ndarray) -> list[list[int]]:
    children = [[] for _ in parents]
    for j, p in enumerate(parents):
        if p >= 0:
            children[p].append(j)
    return children


def _depth_first(children: list[list[int]]) -> list[int]:
    """Joint indices in the order a BVH file lists them (root first, children in index order)."""
    order, stack = [], [0]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(children[j]))
    return order
